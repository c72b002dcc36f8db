"""The band transfers of experiments/twowave_fit.py --transfer (issue 47): measured from
images without a model, they must return a known Gaussian's transfer, and the photo
route's must equal the render route's ratio when both images come from one source."""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
from scipy import ndimage

from tests import ROOT

_PATH = ROOT / "experiments" / "twowave_fit.py"
sys.path.insert(0, str(_PATH.parent))
_SPEC = importlib.util.spec_from_file_location("twowave_fit", _PATH)
twowave_fit = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(twowave_fit)

SIZE = 96


def _texture(seed=0):
    """A textured source: white noise smoothed by 1 px, plus a slow ramp as lighting."""
    rng = np.random.default_rng(seed)
    noise = ndimage.gaussian_filter(rng.normal(size=(SIZE, SIZE)), 1.0, mode="wrap")
    ramp = np.linspace(0.5, 1.5, SIZE)[None, :]
    return 1.0 + 0.3 * noise * ramp


def _blur(image, sigma):
    return ndimage.gaussian_filter(image, sigma, mode="wrap")


def _transfers(images, routes):
    spectra, frequency, sector = twowave_fit._spectra(images, (SIZE, SIZE))
    return twowave_fit.transfer_with_errors(spectra, frequency, sector, routes), frequency, spectra


def test_a_known_gaussian_gives_its_own_transfer_band_by_band():
    source = _texture()
    images = {"s": source, "t": 2.0 * _blur(source, 1.0)}
    (whole, errors, _, _), frequency, spectra = _transfers(images, ((("s", "t", 1),), (("s", "t", 1),)))
    power = np.abs(spectra["s"]) ** 2
    expected = twowave_fit.kernel_transfer([1.0], [1.0], frequency, power)
    # The window smears each band over its neighbours (by about 0.03 where the transfer is
    # under 0.1, the case this test leaves out: 1 px keeps 0.29 in the last band).
    np.testing.assert_allclose(whole[:, 0], expected, atol=0.02)
    assert np.all(errors[1:, 0] < 0.02)
    # Weighted uniformly, the last band's value is the wrong mean of a steep transfer.
    assert abs(whole[-1, 0] - twowave_fit.kernel_transfer([1.0], [1.0], frequency)[-1]) > 0.03
    wider = twowave_fit.kernel_transfer([1.0], [1.3], frequency, power)
    assert np.max(np.abs(whole[:, 0] - wider)) > 0.1


def test_photo_route_equals_render_route_ratio_for_one_source_and_not_otherwise():
    # Kernels with a sharp core, as on the path-traced pair: the extra blur keeps half the
    # contrast at every scale (a core of 0.5 and a 2 px Gaussian).
    source = _texture(1)
    vis = 0.7 * source + 0.3 * _blur(source, 1.5)
    nir = 0.5 * vis + 0.5 * _blur(vis, 2.0)
    routes = ((("vis_t", "nir_t", 1),), (("s", "nir_t", 1), ("s", "vis_t", -1)))
    (whole, _, ratio, _), frequency, spectra = _transfers({"s": source, "vis_t": vis, "nir_t": 3.0 * nir}, routes)
    np.testing.assert_allclose(ratio, 1.0, atol=0.01)
    expected = twowave_fit.kernel_transfer([0.5, 0.5], [0.0, 2.0], frequency, np.abs(spectra["vis_t"]) ** 2)
    np.testing.assert_allclose(whole[:, 0], expected, atol=0.02)
    # A photo route whose visible image is not the render route's (here blurred 1 px more)
    # shows in the ratio.
    routes = ((("vis_photo", "nir_t", 1),), (("s", "nir_t", 1), ("s", "vis_t", -1)))
    images = {"s": source, "vis_t": vis, "vis_photo": _blur(vis, 1.0), "nir_t": nir}
    (_, _, ratio, _), _, _ = _transfers(images, routes)
    assert np.max(ratio[1:]) > 1.1


def test_kernel_transfer_of_a_core_and_a_gaussian_keeps_the_core():
    frequency = np.linspace(0.0, 0.5, 2001)
    core = twowave_fit.kernel_transfer([0.5, 0.5], [0.0, 3.0], frequency)
    # At the last band the 3 px Gaussian has gone; the core's half remains, over the
    # first band's 0.5 + 0.5 * 0.98.
    assert abs(core[-1] - 0.5 / (0.5 + 0.5 * np.mean(np.exp(-2 * np.pi**2 * 9 * np.linspace(0.005, 0.02, 61) ** 2))))\
        < 0.01
