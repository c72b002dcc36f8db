"""`import invsss` stays cheap: heavy dependencies load only when a name needs them."""

from __future__ import annotations

import pytest
import json
import subprocess
import sys

_HEAVY = ("OpenImageIO", "optimistix", "skimage", "matplotlib")


def _loaded_after(code: str) -> list[str]:
    """The heavy modules present in ``sys.modules`` after running ``code`` in a fresh process."""
    script = f"import sys\n{code}\nimport json\nprint(json.dumps([m for m in {_HEAVY!r} if m in sys.modules]))"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_rendering_arrays_imports_no_heavy_dependency():
    code = (
        "import numpy as np, invsss\n"
        "p = invsss.SSSParams(50.0, 0.0, 1.0, [1.0], [0.5])\n"
        "out = invsss.render(np.ones((8, 8, 3), np.float32), np.full((8, 8), 500.0, np.float32),"
        " np.ones((8, 8), np.float32), p)\n"
        "assert out.shape == (8, 8, 3)"
    )
    assert _loaded_after(code) == []


@pytest.mark.slow
def test_params_files_do_not_import_openimageio(tmp_path):
    path = json.dumps(str(tmp_path / "p.json"))
    code = (
        "import invsss.io as io\n"
        f"io.write_params({path}, invsss.SSSParams(50.0, 0.0, 1.0, [1.0], [0.5]))\n"
        f"io.read_params({path})"
    )
    assert "OpenImageIO" not in _loaded_after("import invsss\n" + code)


def test_lazy_names_resolve_to_their_modules():
    import invsss
    from invsss.estimator import fit_pair
    from invsss.io import read_image

    assert invsss.read_image is read_image
    assert invsss.fit_pair is fit_pair
    assert "read_image" in dir(invsss) and "read_image" in invsss.__all__


def test_reading_an_image_imports_openimageio(tmp_path):
    path = json.dumps(str(tmp_path / "a.png"))
    code = (
        "import numpy as np, invsss\n"
        f"invsss.write_image({path}, np.full((4, 4), 0.5, np.float32))\n"
        f"invsss.read_image({path})"
    )
    assert _loaded_after(code) == ["OpenImageIO"]
