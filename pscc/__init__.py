"""pscc: parallel self-collision culling (PSCC, I3D 2018) and cloth simulation on NVIDIA Warp."""

from __future__ import annotations

__version__ = "0.1.0"
