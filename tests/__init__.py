"""The tests, one folder per layer of invsss (docs/architecture.md, "Layers").

``tests/<layer>/`` tests ``invsss/<layer>/`` and may use only that layer and the
layers below it, through public names (``tests/test_layers.py`` checks it). A
feature that spans layers has a file in each (``forward/test_light_terms.py`` for
the model, ``estimator/test_light_terms.py`` for its fit,
``cli/test_light_terms.py`` for the command line). The files here test the package
as a whole; ``scripts/`` tests the scripts in ``experiments/`` and the data they
made. Shared fixtures are in ``conftest.py``; helpers that build inputs are the
``_*.py`` modules of the lowest folder whose layer they use.
"""

from pathlib import Path

#: The repository's root: data_synthetic/, docs/, experiments/ and invsss/ are in it.
ROOT = Path(__file__).resolve().parent.parent
