"""The split of the bundled path-traced pairs into tuning and held-out pairs.

``data_synthetic/SPLIT.toml`` names, once, which pairs a method may be tuned on
(``tuning``) and which are only measured on (``held-out``); see docs/scenes.md.
:func:`read_split` reads and checks it.
"""

from __future__ import annotations

import os
import tomllib

from ..validation import InvalidInputError

__all__ = ["SPLITS", "read_split", "pair_split"]

#: The two parts, in the order reports list them.
SPLITS = ("tuning", "held-out")


def read_split(path) -> dict[str, str]:
    """``{pair folder name: "tuning" or "held-out"}`` from a SPLIT.toml file.

    The file has exactly the keys ``tuning`` and ``held-out``, each a list of
    folder names; a name may appear once only.

    Raises
    ------
    InvalidInputError
        An unreadable file, bad TOML, a missing or unknown key, a value that is not
        a list of names, or a name listed twice (one line naming it).

    Examples
    --------
    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "SPLIT.toml")
    >>> _ = open(path, "w").write('tuning = ["a", "b"]\\nheld-out = ["c"]\\n')
    >>> read_split(path)
    {'a': 'tuning', 'b': 'tuning', 'c': 'held-out'}
    >>> _ = open(path, "w").write('tuning = ["a"]\\nheld-out = ["a"]\\n')
    >>> read_split(path)
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: ...SPLIT.toml: a is listed as tuning and as held-out
    """
    name = os.fspath(path)
    try:
        with open(name, "rb") as f:
            content = tomllib.load(f)
    except OSError as err:
        raise InvalidInputError(f"{name}: cannot read the split file ({err.strerror})", field=name) from None
    except tomllib.TOMLDecodeError as err:
        raise InvalidInputError(f"{name}: not valid TOML ({err})", field=name) from None
    unknown = sorted(set(content) - set(SPLITS))
    if unknown:
        raise InvalidInputError(f"{name}: {unknown[0]}: unknown key (valid: {', '.join(SPLITS)})", field=name)
    split: dict[str, str] = {}
    for part in SPLITS:
        if part not in content:
            raise InvalidInputError(f"{name}: {part}: missing", field=name)
        names = content[part]
        if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
            raise InvalidInputError(f"{name}: {part}: expected a list of pair folder names", field=name)
        for pair in names:
            if pair in split:
                raise InvalidInputError(f"{name}: {pair} is listed as {split[pair]} and as {part}", field=name)
            split[pair] = part
    return split


def pair_split(folder, split: dict[str, str]) -> str | None:
    """The part a pair folder belongs to (by its name), or None if the split does not list it.

    Examples
    --------
    >>> pair_split("data_synthetic/pt_face_940/", {"pt_face_940": "tuning"})
    'tuning'
    """
    return split.get(os.path.basename(os.path.normpath(os.fspath(folder))))
