"""The Vulkan device the reference shader's tests run on (tests/io/test_shader*.py)."""

from __future__ import annotations

import pytest

from invsss.shaders import find_compiler
from tests.io._shaders import adapter_names

_ADAPTERS = None


@pytest.fixture(params=["cpu", "gpu"])
def device(request):
    """The Vulkan device's name: lavapipe (``cpu``), or a GPU where there is one."""
    global _ADAPTERS
    if find_compiler() is None:
        pytest.skip("glslangValidator not found: apt-get install glslang-tools (CI's .ci/run does)")
    try:
        import wgpu  # noqa: F401
    except ImportError:
        pytest.skip('wgpu not installed: pip install "invsss[shader]" (the test extra has it)')
    if _ADAPTERS is None:
        _ADAPTERS = adapter_names()
    name = _ADAPTERS[request.param]
    if name is None:
        if request.param == "cpu":
            pytest.skip("no CPU Vulkan device: apt-get install mesa-vulkan-drivers (lavapipe; CI's .ci/run does)")
        pytest.skip("no Vulkan GPU on this machine (the cpu variant ran on lavapipe)")
    return name
