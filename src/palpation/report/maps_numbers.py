"""The vessel maps' figures in docs/maps.md: the Silicone pose reconstruction's measures and checks, read from
docs/results/paper/maps/silicone_pose_check.json (written by the maps' silicone_check). Registered in
report.docnumbers.
"""

from __future__ import annotations

from pathlib import Path

from palpation.readers import read_json
from palpation.report.records import FIX

SILICONE_CHECK = "paper/maps/silicone_pose_check.json"  # written by the maps' silicone_check (docs/maps.md)


def _signed(value: float, digits: int = 1) -> str:
    return f"{value:+.{digits}f}".replace("-", "−")


def silicone_check(results: Path, what: str) -> str:
    """The Silicone pose reconstruction's measures and checks, as docs/maps.md states them."""
    record = read_json(results / SILICONE_CHECK, FIX, "record", kind=dict, keys=("check", "directions", "mirror"))
    check, mirror, videos = record["check"], record["mirror"], record["directions"]
    if what == "dot_steps":
        steps = [abs(v["dot_step_px"]) for v in videos if v["dot_step_px"] is not None]
        return f"±{min(steps):.0f} to ±{max(steps):.0f} px/frame"
    if what == "drift":
        neg = sorted((v["marker_drift_px"] for v in videos if v["marker_drift_px"] < 0), reverse=True)
        pos = sorted(v["marker_drift_px"] for v in videos if v["marker_drift_px"] > 0)
        return f"{_signed(neg[0])} to {_signed(neg[-1])} px against {_signed(pos[0])} to {_signed(pos[-1])} px"
    if what == "drift_dotfree":
        free = [v for v in videos if v["dot_step_px"] is None]
        return (f"{'–'.join(str(v['video']) for v in free)} ("
                + " / ".join(_signed(v["marker_drift_px"]) for v in free) + " px)")
    if what == "mirror":
        per_path = " / ".join(f"{p['m']:.2f}" for _, p in sorted(mirror["per_path"].items()))
        return f"**m = {mirror['m']:.2f}** ({mirror['n']} pairs, std {mirror['std']:.2f}; per path {per_path})"
    if what == "step":
        return f"{60 / mirror['m']:.2f} mm"
    if what == "iou":
        return f"**{check['iou_video_photo']:.3f}**"
    if what in ("dots", "video_truth"):
        d = check["dots_to_photo_mm" if what == "dots" else "video_truth_to_photo_mm"]
        mean = f"**{d['mean']:.2f} mm**" if what == "dots" else f"{d['mean']:.2f} mm"
        return f"mean {mean}, median {d['median']:g}, p90 {d['p90']:g} mm"
    if what == "dots_n":
        return str(check["dots_to_photo_mm"]["n"])
    if what == "dots_mean":
        return f"{check['dots_to_photo_mm']['mean']:.2f} mm"
    raise ValueError(f"unknown Silicone check measure {what}")


SILICONE_MEASURES = ("dot_steps", "drift", "drift_dotfree", "mirror", "step", "iou", "dots", "video_truth", "dots_n",
                     "dots_mean")
