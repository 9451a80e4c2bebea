"""Shared fixtures: every device test runs on the CPU, and on CUDA when a GPU is present."""

from __future__ import annotations

import pytest
import warp as wp

wp.config.log_level = wp.LOG_WARNING
wp.init()


def _devices() -> list[str]:
    devices = ["cpu"]
    if wp.is_cuda_available():
        devices.append("cuda:0")
    return devices


@pytest.fixture(params=_devices())
def device(request: pytest.FixtureRequest) -> str:
    """Warp device name to run on."""
    return request.param
