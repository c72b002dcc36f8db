"""The reference shader's files beside exported constants (``invsss export --with-shader``).

:func:`shader_files` says which files a fit uses (its model's shader and its
light terms', :mod:`invsss.shaders`) and :func:`write_shader` writes them as a
set, beside a constants file whose name they include. Both are re-exported by
:mod:`invsss.io.export`.
"""

from __future__ import annotations

import os

from ..validation import InvalidInputError
from .light_constants import light_constants
from .writing import write_texts_atomic

__all__ = ["shader_files", "write_shader"]

#: The light terms' shader files, by the constant that says a fit uses them
#: (:func:`~invsss.io.export.shader_constants` writes ``lawAlbedo`` with the law, ``lightShift``
#: with a term after the blur, ``transmissionTint`` with the transmission).
_LIGHT_TERM_SHADERS = {"lawAlbedo": "invsss_law.hlsl", "lightShift": "invsss_light_terms.hlsl",
                       "transmissionTint": "invsss_transmission.hlsl"}


def shader_files(constants_path, model: str | None = None, light_terms=None) -> dict[str, str]:
    """The reference shader files that go beside a constants file: path to text.

    Parameters
    ----------
    constants_path : str or os.PathLike
        The constants file; the shader files sit in its folder and include it
        by its file name (instead of ``invsss_constants.hlsl``).
    model : str, optional
        The fit's model: its shader's files (:func:`invsss.shaders.shader_sources`),
        and the light terms' files the fit's ``light_terms`` use. Default: every
        shader file.
    light_terms : LightTerms or mapping, optional
        As in :func:`~invsss.io.export.shader_constants` (a params file's ``light_terms``).

    Raises
    ------
    InvalidInputError
        A model without a reference shader, light terms that
        :func:`~invsss.io.export.shader_constants` refuses, or ``constants_path`` named like one
        of the shader files.
    """
    from ..shaders import SHADER_FILES, shader_sources

    constants_path = os.fspath(constants_path)
    name = os.path.basename(constants_path)
    sources = shader_sources(name) if model is None else shader_sources(name, model=model)
    if model is not None and light_terms is not None:
        used = light_constants(light_terms)
        every = shader_sources(name)
        sources.update({file: every[file] for key, file in _LIGHT_TERM_SHADERS.items() if key in used})
    folder = os.path.dirname(os.path.abspath(constants_path))
    files = {}
    for file in SHADER_FILES:
        if file not in sources:
            continue
        path = os.path.join(folder, file)
        if os.path.abspath(path) == os.path.abspath(constants_path):
            raise InvalidInputError(f"{constants_path}: has the name of a shader file; choose another name",
                                    field=constants_path)
        files[path] = sources[file]
    return files


def write_shader(constants_path, model: str | None = None, *, light_terms=None, overwrite: bool = False) -> list:
    """Write the reference shader (``invsss/shaders/*.hlsl``, docs/renderer.md) beside a constants file.

    The files of :func:`shader_files`, each including ``constants_path``'s file
    name for the constants. They are written as a set: all are checked first,
    and none is written when one cannot be (:func:`invsss.io.writing.write_texts_atomic`).

    Parameters
    ----------
    constants_path : str or os.PathLike
        The constants file (:func:`~invsss.io.export.to_hlsl`), written or to be written.
    model, light_terms
        As in :func:`shader_files`: only the files a fit of ``model`` with
        these light terms uses (default: every file).
    overwrite : bool
        Replace shader files already there; otherwise an existing one is refused.

    Returns
    -------
    list of str
        The paths written.

    Raises
    ------
    InvalidInputError
        As :func:`shader_files`, or a file that is there (without ``overwrite``),
        a folder in a file's way, or a folder that cannot be written to.
    """
    files = shader_files(constants_path, model, light_terms)
    return write_texts_atomic(files, overwrite=overwrite, roles=dict.fromkeys(files, "a shader file"))
