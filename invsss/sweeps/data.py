"""Which pairs an experiment uses: folders, globs and explicit file sets.

A pair folder holds ``source.exr``, ``target.exr``, ``depth.exr`` and ``mask.png``
(the layout of ``data_synthetic/``), and may hold ``normal.exr``, ``light.exr`` and
``key.exr`` (the light-aware terms' buffers, which ``invsss scene`` writes); a glob such as ``data_synthetic/*/`` names
every pair folder it matches, in sorted order (other folders it matches, such
as ``LICENSES/``, are passed over). Paths are relative to the experiment
file's folder, so an experiment runs the same from any working directory. Each
pair gets a name (the folder's name, or ``name`` of a file set) that trials and
reports use; names must be unique.

Files are only located here, not read: a pair whose files exist but cannot be
read fails its own trials, not the whole experiment.
"""

from __future__ import annotations

import glob
import os

from ..validation import InvalidInputError
from .schema import DataSpec

__all__ = ["PAIR_FILES", "BUFFER_FILES", "resolve_pairs"]

#: The files of a pair folder, by role.
PAIR_FILES = {"source": "source.exr", "target": "target.exr", "depth": "depth.exr", "mask": "mask.png"}

#: Optional files of a pair folder: the buffers of the light-aware terms
#: (:class:`invsss.LightBuffers`), recorded when present.
BUFFER_FILES = {"normal": "normal.exr", "light": "light.exr", "key": "key.exr", "fill_light": "fill_light.exr",
                "thickness": "thickness.exr", "key_irradiance": "key_irradiance.exr"}


def _relative(path: str, root: str) -> str:
    return os.path.relpath(os.path.normpath(os.path.join(root, path)), root)


def resolve_pairs(data: DataSpec, root: str, name: str) -> list[dict]:
    """The pairs of ``data`` as ``{"name", "source", "target", "depth", "mask"}`` dicts,
    with ``"normal"``, ``"light"``, ``"key"``, ``"fill_light"``, ``"thickness"`` and
    ``"key_irradiance"`` where the folder or file set has them.

    Paths in the result are relative to ``root`` (the experiment file's folder)
    and normalised, so the same experiment gives the same trial ids wherever it
    is run from.

    Raises
    ------
    InvalidInputError
        A pattern that matches nothing, a folder without one of the four files,
        a file set naming a missing file, two pairs with the same name, or no
        pairs at all (``name`` is the experiment file, for the message).

    Examples
    --------
    >>> import os, tempfile
    >>> root = tempfile.mkdtemp(); os.mkdir(os.path.join(root, "a"))
    >>> for f in PAIR_FILES.values(): open(os.path.join(root, "a", f), "w").close()
    >>> [p["name"] for p in resolve_pairs(DataSpec(pairs=["*/"]), root, "e.toml")]
    ['a']
    """
    pairs: list[dict] = []
    for pattern in data.pairs:
        matches = sorted(glob.glob(os.path.join(root, pattern)))
        folders = [m for m in matches if os.path.isdir(m)]
        if not folders:
            raise InvalidInputError(
                f"{name}: data.pairs: {pattern!r} matches no folder (relative to {root})"
            )
        if glob.has_magic(pattern):
            # A glob picks the pair folders among its matches (data_synthetic/*/
            # also matches LICENSES/); a folder named outright must be a pair.
            folders = [f for f in folders if all(os.path.isfile(os.path.join(f, n)) for n in PAIR_FILES.values())]
            if not folders:
                raise InvalidInputError(
                    f"{name}: data.pairs: {pattern!r} matches no pair folder (one holding "
                    f"{', '.join(PAIR_FILES.values())})"
                )
        for folder in folders:
            files = {}
            for role, file in PAIR_FILES.items():
                path = os.path.join(folder, file)
                if not os.path.isfile(path):
                    # A folder named outright, as the user wrote it ('../x/' is '.' relative to the file).
                    shown = pattern if not glob.has_magic(pattern) else os.path.relpath(folder, root)
                    raise InvalidInputError(
                        f"{name}: data.pairs: {shown!r}"
                        f" has no {file} "
                        f"(a pair folder holds {', '.join(PAIR_FILES.values())})"
                    )
                files[role] = _relative(path, root)
            for role, file in BUFFER_FILES.items():
                if os.path.isfile(os.path.join(folder, file)):
                    files[role] = _relative(os.path.join(folder, file), root)
            pairs.append({"name": os.path.basename(os.path.normpath(folder)), **files})
    for i, fileset in enumerate(data.files):
        files = {}
        for role in PAIR_FILES:
            path = getattr(fileset, role)
            if not os.path.isfile(os.path.join(root, path)):
                raise InvalidInputError(f"{name}: data.files[{i}].{role}: {path} not found (relative to {root})")
            files[role] = _relative(path, root)
        for role in BUFFER_FILES:
            path = getattr(fileset, role)
            if path is None:
                continue
            if not os.path.isfile(os.path.join(root, path)):
                raise InvalidInputError(f"{name}: data.files[{i}].{role}: {path} not found (relative to {root})")
            files[role] = _relative(path, root)
        label = fileset.name or os.path.splitext(os.path.basename(files["source"]))[0]
        pairs.append({"name": label, **files})
    if not pairs:
        raise InvalidInputError(f"{name}: data: no pairs; give data.pairs (folders or globs) or data.files")
    seen = set()
    for pair in pairs:
        if pair["name"] in seen:
            raise InvalidInputError(
                f"{name}: data: two pairs are named {pair['name']!r}; give the file sets distinct names"
            )
        seen.add(pair["name"])
    return pairs
