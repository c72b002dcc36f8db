"""Writing files atomically: images encoded for their format, and text.

Writers write a temporary file next to the target and ``os.replace`` it, so an
interrupted run never leaves half a file behind. Images are linear float
values, encoded for the file type (sRGB bytes for 8-bit files, linear for the
rest; see :func:`write_image`).
"""

from __future__ import annotations

import contextlib
import os
import secrets

import numpy as np

from ..validation import InvalidInputError, check_image, one_line
from .colour import linear_to_srgb
from .rasters import image_extension, openimageio

__all__ = ["write_image", "write_text_atomic", "write_texts_atomic", "check_file_target", "atomic_output",
           "same_file"]

# Bits written for each extension when write_image is not told (EXR/TIFF keep
# full float precision, PNG/JPEG are 8-bit sRGB like any viewer expects).
_DEFAULT_BITS = {".exr": 32, ".png": 8, ".tif": 32, ".tiff": 32, ".jpg": 8, ".jpeg": 8, ".npy": 32}
_ALLOWED_BITS = {
    ".exr": (16, 32),
    ".png": (8, 16),
    ".tif": (8, 16, 32),
    ".tiff": (8, 16, 32),
    ".jpg": (8,),
    ".jpeg": (8,),
    ".npy": (32,),
}


@contextlib.contextmanager
def _atomic_target(path: str):
    """Yield a temporary sibling of ``path``; on success it replaces ``path``."""
    directory, base = os.path.split(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise InvalidInputError(f"{path}: cannot write, directory {directory} does not exist", path=path)
    ext = os.path.splitext(base)[1]
    # Same directory (so os.replace is a rename on one file system) and the same
    # extension (OpenImageIO picks the format from it); hidden while incomplete.
    temporary = os.path.join(directory, f".{base}.{secrets.token_hex(4)}.tmp{ext}")
    try:
        yield temporary
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.remove(temporary)
        raise


def _write_temporary(temporary: str, text: str) -> None:
    with open(temporary, "x", encoding="utf-8") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())


def write_text_atomic(path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` so that an interrupted run leaves no half file."""
    with _atomic_target(os.fspath(path)) as temporary:
        _write_temporary(temporary, text)


def same_file(a, b) -> bool:
    """Whether ``a`` and ``b`` are one existing regular file, through any path or link
    (False where either is missing or cannot be examined)."""
    try:
        return os.path.isfile(a) and os.path.isfile(b) and os.path.samefile(a, b)
    except OSError:
        return False


def check_file_target(path, *, overwrite: bool, option: str = "--overwrite", role: str = "") -> None:
    """Raise unless a file can be written at ``path`` without losing anything.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    overwrite : bool
        Whether an existing file at ``path`` may be replaced.
    option : str
        How the user says ``overwrite``, for the message (``"--overwrite"``).
    role : str
        What the file is, for the message of a folder in its way (``"the
        shader file"``); default: the output file.

    Raises
    ------
    InvalidInputError
        Its folder is missing, is a file or cannot be written to (by
        permission; a write can still fail later, which :func:`write_texts_atomic`
        reports the same way), ``path`` is a folder or another non-file, or
        ``path`` is a file and ``overwrite`` is false.
    """
    name = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(name))
    if not os.path.isdir(directory):
        if os.path.lexists(directory):
            raise InvalidInputError(f"{name}: cannot write, {directory} is a file, not a folder", field=name)
        raise InvalidInputError(f"{name}: cannot write, directory {directory} does not exist", field=name)
    what = role or "the output file"
    if os.path.isdir(name):
        raise InvalidInputError(f"{name}: is a folder, in the way of {what}; name a file, or move the folder away",
                                field=name)
    if os.path.lexists(name) and not os.path.isfile(name):
        raise InvalidInputError(f"{name}: is in the way of {what} (not a regular file); move it away", field=name)
    if os.path.lexists(name) and not overwrite:
        raise InvalidInputError(f"{name}: already exists; pass {option} to replace it", field=name)
    if not os.access(directory, os.W_OK | os.X_OK):
        raise InvalidInputError(f"{name}: cannot write, folder {directory} is not writable", field=name)


def write_texts_atomic(files, *, overwrite: bool = False, option: str = "--overwrite",
                       roles=None) -> list[str]:
    """Write a set of text files (UTF-8): every one whole, and none when one cannot be.

    Every target is checked first (:func:`check_file_target`), then every text
    is written to a hidden temporary file beside its target, and only then are
    the temporaries renamed over the targets. A failure before the renames
    (a check, a full disk, a folder that refuses the temporary) leaves every
    target as it was; the renames themselves (one ``os.replace`` each, on one
    file system) fail only when the file system changes under the run.

    Parameters
    ----------
    files : mapping of str or os.PathLike to str
        Path to text, in the order to write them.
    overwrite : bool
        Whether existing files may be replaced (default: refused).
    option : str
        How the user says ``overwrite``, for the message.
    roles : mapping of path to str, optional
        What each file is, for the message of a folder in its way.

    Returns
    -------
    list of str
        The paths written, in order.

    Raises
    ------
    InvalidInputError
        One line naming the first file that cannot be written and why.

    Examples
    --------
    >>> import os, tempfile
    >>> folder = tempfile.mkdtemp()
    >>> a, b = os.path.join(folder, "a.txt"), os.path.join(folder, "b.txt")
    >>> [os.path.basename(p) for p in write_texts_atomic({a: "one\\n", b: "two\\n"})]
    ['a.txt', 'b.txt']
    >>> write_texts_atomic({a: "three\\n"})  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    invsss.validation.InvalidInputError: ...a.txt: already exists; pass --overwrite to replace it
    """
    texts = {os.fspath(path): text for path, text in files.items()}
    roles = {os.fspath(path): role for path, role in (roles or {}).items()}
    for path in texts:
        check_file_target(path, overwrite=overwrite, option=option, role=roles.get(path, ""))
    temporaries: dict[str, str] = {}
    current = None
    try:
        for current, text in texts.items():
            directory, base = os.path.split(os.path.abspath(current))
            temporaries[current] = os.path.join(directory, f".{base}.{secrets.token_hex(4)}.tmp")
            _write_temporary(temporaries[current], text)
        for current, temporary in temporaries.items():
            os.replace(temporary, current)
    except OSError as err:
        raise InvalidInputError(f"{current}: cannot write ({err.strerror or err})", field=current) from None
    finally:
        for temporary in temporaries.values():
            with contextlib.suppress(OSError):
                os.remove(temporary)
    return list(texts)


@contextlib.contextmanager
def atomic_output(path):
    """A temporary sibling of ``path`` to write to; on success it replaces ``path``.

    As the writers of this module do it, for a writer that takes a path
    (``figure.savefig``, ``DataFrame.to_parquet``): the temporary has ``path``'s
    extension. An ``OSError`` (a read-only folder, a full disk) becomes an
    :class:`~invsss.validation.InvalidInputError` naming ``path``, and the
    temporary is removed, so ``path`` is either the old file or the whole new one.
    """
    name = os.fspath(path)
    try:
        with _atomic_target(name) as temporary:
            yield temporary
    except OSError as err:
        raise InvalidInputError(f"{name}: cannot write ({err.strerror or err})", field=name) from None


def _encode(image: np.ndarray, bits: int, ext: str) -> tuple[np.ndarray, str, str | None]:
    """Pixels for the file, their OpenImageIO type and the colour space to declare."""
    if bits == 32:
        return image.astype(np.float32), "float", None
    if bits == 16 and ext == ".exr":
        return image.astype(np.float32), "half", None
    if bits == 8:
        encoded = linear_to_srgb(np.clip(image, 0.0, 1.0))
        return np.round(encoded * 255.0).astype(np.uint8), "uint8", "srgb_rec709_scene"
    linear = np.clip(image.astype(np.float64), 0.0, 1.0)
    # Declared linear: a PNG gets gAMA = 1.0, so any reader knows it is not sRGB.
    return np.round(linear * 65535.0).astype(np.uint16), "uint16", "lin_rec709_scene"


def write_image(path, image, *, bits: int | None = None) -> None:
    """Write a linear float image, encoded for the file type, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        ``.exr``, ``.png``, ``.tif``/``.tiff``, ``.jpg``/``.jpeg`` or ``.npy``.
    image : array, shape (H, W) or (H, W, C), C in {1, 3}
        Linear values; must be finite.
    bits : int, optional
        32: float (default for EXR, TIFF, NPY). 16: half for EXR, else 16-bit
        linear integers declared linear. 8: sRGB-encoded bytes (default for PNG
        and JPEG). Integer encodings clip to [0, 1] first.

    Raises
    ------
    InvalidInputError
        Bad shape or values, unsupported extension or bit depth, a missing
        directory, or a write failure.

    Examples
    --------
    >>> import numpy as np, tempfile, os, invsss
    >>> path = os.path.join(tempfile.mkdtemp(), "out.exr")
    >>> invsss.write_image(path, np.full((4, 4, 3), 0.25, np.float32))
    >>> float(invsss.read_image(path).mean())
    0.25
    """
    name = os.fspath(path)
    ext = image_extension(name, "image")
    bits = _DEFAULT_BITS[ext] if bits is None else bits
    if bits not in _ALLOWED_BITS[ext]:
        raise InvalidInputError(
            f"{name}: cannot write {bits}-bit {ext} files, expected bits in {_ALLOWED_BITS[ext]}",
            field=name,
        )
    image = np.asarray(image)
    check_image(image, f"image for {name}")
    if image.ndim == 2:
        image = image[..., None]
    pixels, pixel_type, colour_space = _encode(image, bits, ext)
    # OpenImageIO takes C-ordered pixels only; a read image or a slice may be strided.
    pixels = np.ascontiguousarray(pixels)

    with _atomic_target(name) as temporary:
        if ext == ".npy":
            with open(temporary, "xb") as f:
                np.save(f, pixels if pixels.shape[2] > 1 else pixels[..., 0])
            return
        oiio = openimageio()
        height, width, channels = pixels.shape
        spec = oiio.ImageSpec(width, height, channels, pixel_type)
        if colour_space is not None:
            spec.attribute("oiio:ColorSpace", colour_space)
        if ext in (".jpg", ".jpeg"):
            # High quality and no chroma subsampling: these are data, not thumbnails.
            spec.attribute("Compression", "jpeg:95")
            spec.attribute("jpeg:subsampling", "4:4:4")
        output = oiio.ImageOutput.create(temporary)
        if output is None:
            raise InvalidInputError(f"{name}: cannot write ({one_line(oiio.geterror())})", field=name)
        ok = output.open(temporary, spec) and output.write_image(pixels)
        error = one_line(output.geterror())
        ok = output.close() and ok
        if not ok:
            raise InvalidInputError(f"{name}: cannot write ({error or 'unknown error'})", field=name)
