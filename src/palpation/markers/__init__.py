"""Marker detection (OpenCV), the canonical 127-marker template and ordering, frame-to-frame tracking."""
