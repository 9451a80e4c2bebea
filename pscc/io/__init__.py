"""Output files of the simulator: atomic writes, NPZ frames and the stats file."""

from pscc.io.frames import FRAME_KEYS, frame_path, read_frame, write_frame, write_json_atomic

__all__ = ["FRAME_KEYS", "frame_path", "read_frame", "write_frame", "write_json_atomic"]
