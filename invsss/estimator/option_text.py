"""Fit options written as text: the command line's spellings of :class:`FitOptions` fields.

Each function turns one field's text (``--fix maxdd=0.05``, ``--canvas 256x256``,
``--saturation auto``) into the value :class:`~.options.FitOptions` takes, or
raises a one-line :class:`~invsss.validation.InvalidInputError` naming the flag.
:class:`~.options.FitOptions` names them in its fields' metadata, so the command
line (:mod:`invsss.cli.fit`) builds its arguments from the fields alone.
"""

from __future__ import annotations

from ..validation import InvalidInputError

__all__ = ["FIX_LISTS", "FIX_SCALARS", "canvas_from_text", "fix_from_text", "saturation_from_text"]

#: Parameters ``fix`` holds at one number, and at a list of numbers.
FIX_SCALARS = ("sss_level", "correction", "maxdd")
FIX_LISTS = ("weights", "variances")


def canvas_from_text(text: str | None, flag: str = "--canvas") -> tuple[int, int] | None:
    """``"HxW"``: two integers >= 1 (None when not given).

    Examples
    --------
    >>> canvas_from_text("256x320")
    (256, 320)
    >>> canvas_from_text("256")
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: --canvas '256': expected HxW, two integers >= 1 (e.g. 256x256)
    """
    if text is None:
        return None
    height, sep, width = text.lower().partition("x")
    try:
        size = int(height), int(width)
        if not sep or min(size) < 1:
            raise ValueError(text)
        return size
    except ValueError:
        raise InvalidInputError(f"{flag} {text!r}: expected HxW, two integers >= 1 (e.g. 256x256)",
                                field=flag) from None


def saturation_from_text(text: str, flag: str = "--saturation") -> float | str | None:
    """A number, ``"none"`` (None) or ``"auto"`` (kept: the caller resolves it from
    the targets' files, :func:`invsss.io.shared_clipping_level`).

    Examples
    --------
    >>> saturation_from_text("0.98"), saturation_from_text("none"), saturation_from_text("auto")
    (0.98, None, 'auto')
    """
    if text in ("auto", None):
        return text
    if text == "none":
        return None
    try:
        return float(text)
    except ValueError:
        raise InvalidInputError(f"{flag} {text!r}: expected auto, none or a number > 0", field=flag) from None


def fix_from_text(items: list[str], flag: str = "--fix") -> dict | None:
    """``["maxdd=0.05", "variances=0.5,2"]`` -> ``{"maxdd": 0.05, "variances": [0.5, 2.0]}``
    (None for no items).

    Examples
    --------
    >>> fix_from_text(["maxdd=0.05", "variances=0.5,2"])
    {'maxdd': 0.05, 'variances': [0.5, 2.0]}
    >>> fix_from_text(["depth=3"])
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: --fix 'depth=3': unknown parameter 'depth', expected one of sss_level, correction, maxdd, weights, variances
    """  # noqa: E501
    known = FIX_SCALARS + FIX_LISTS
    fixed: dict = {}
    for item in items:
        name, equals, text = (part.strip() for part in item.partition("="))
        if not equals or not name or not text:
            raise InvalidInputError(f"{flag} {item!r}: expected NAME=VALUE, e.g. maxdd=0.05 or variances=0.5,2",
                                    field=flag)
        if name not in known:
            raise InvalidInputError(f"{flag} {item!r}: unknown parameter {name!r}, expected one of {', '.join(known)}",
                                    field=flag)
        if name in fixed:
            raise InvalidInputError(f"{flag} {item!r}: {name} is given more than once", field=flag)
        try:
            numbers = [float(t) for t in text.split(",")]
        except ValueError:
            raise InvalidInputError(
                f"{flag} {item!r}: expected " + ("a number" if name in FIX_SCALARS else "comma-separated numbers")
            ) from None
        if name in FIX_SCALARS:
            if len(numbers) != 1:
                raise InvalidInputError(f"{flag} {item!r}: {name} takes a single number", field=flag)
            fixed[name] = numbers[0]
        else:
            fixed[name] = numbers
    return fixed or None
