"""ViTacTip sliding-palpation twin: camera, markers, real data, Warp FEM twin, calibration, GNN."""

__version__ = "0.1.0"
