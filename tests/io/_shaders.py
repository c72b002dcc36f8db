"""The bundled pairs, the devices and a params file with every light term, for the
reference shader's tests (tests/io/test_shader*.py, tests/cli/test_shader_export.py)."""

from __future__ import annotations

import numpy as np
import pytest

from invsss.forward.pair import fill_background_depth
from invsss.io import read_depth, read_image, read_mask, write_params
from invsss.shaders import find_compiler, vulkan_adapters
from tests import ROOT

DATA = ROOT / "data_synthetic"
#: The acceptance bound of issue 32: max |shader - render| under this fraction of the peak.
TOLERANCE = 1e-4


def adapter_names():
    """The name of a CPU (lavapipe) and of a GPU Vulkan device, each None where there is none."""
    adapters = vulkan_adapters()
    cpu = [a.info["device"] for a in adapters if str(a.info.get("adapter_type", "")).lower() == "cpu"]
    gpu = [a.info["device"] for a in adapters if str(a.info.get("adapter_type", "")).lower() != "cpu"]
    return {"cpu": cpu[0] if cpu else None, "gpu": gpu[0] if gpu else None}


def pair(name):
    """A bundled pair's source, depth (background filled) and mask, in float32."""
    d = DATA / name
    image = read_image(d / "source.exr", linear=True)
    image = image if image.ndim == 3 else image[..., None]
    mask = read_mask(d / "mask.png").astype(np.float32)
    depth = fill_background_depth(read_depth(d / "depth.exr")).astype(np.float32)
    return image.astype(np.float32), depth, mask


def relative_error(got, want):
    return float(np.abs(got - want).max() / np.abs(want).max())


#: Skips a test that compiles a shader where there is no compiler.
needs_compiler = pytest.mark.skipif(
    find_compiler() is None, reason="glslangValidator not found: apt-get install glslang-tools (CI's .ci/run does)"
)


def params_file(path, model):
    """A params file of ``model`` with RGB weights and every light term but the fill."""
    write_params(path, {"sss_level": 612.3, "correction": 800.0, "maxdd": 0.5,
                        "weights": [[0.2, 0.5, 0.9], [0.6, 0.4, 0.1], [0.2, 0.1, 0.0]],
                        "variances": [2.5, 0.4, 8.7], "model": model,
                        "light_terms": {"shift": 1.2, "grazing": 0.3, "incidence": 0.15,
                                        "law": [0.93, 0.8, 0.7], "law_strength": 0.9}})
    return path
