"""Exported HLSL read back for the export tests: a ``static const`` block parsed
(:func:`parse_hlsl`), and the law snippet (invsss.io.export.LAW_HLSL) run as NumPy."""

from __future__ import annotations

import re

import numpy as np


class _Vector(np.ndarray):
    """A float3 with HLSL's ``.x``, ``.y``, ``.z``."""

    x = property(lambda self: float(self[0]))
    y = property(lambda self: float(self[1]))
    z = property(lambda self: float(self[2]))


def _hlsl_function_as_python(text: str, name: str):
    """The body of an HLSL function of :data:`invsss.io.export.LAW_HLSL`, run as NumPy.

    The snippet is plain arithmetic on float and float3 values; a handful of
    substitutions make each statement Python, so the test runs the shader's own
    text rather than a copy of its formula.
    """
    body = text[text.index(name):]
    body = body[body.index("{") + 1: body.index("\n}")]
    lines = []
    for statement in body.strip().split(";"):
        statement = " ".join(statement.split())
        if not statement:
            continue
        statement = re.sub(r"^(float3|float) ", "", statement)
        statement = statement.replace("return ", "result = ")
        lines.append(statement)
    return "\n".join(lines)


def hlsl_law_factor(hlsl: str, name: str, constants: dict, prefix: str = "sss_"):
    """The law factor ``name`` of a constants text (``invsssKeyLightLaw`` or
    ``invsssOtherLightLaw``) as a Python function of one pixel's normal and light
    direction, run from the shader's own text with the constants' values."""
    hapke = _hlsl_function_as_python(hlsl, "float3 invsssHapkeH")
    factor = _hlsl_function_as_python(hlsl, f"float3 {name}")
    helpers = {
        "np": np,
        "sqrt": np.sqrt,
        "max": np.maximum,
        "clamp": np.clip,
        "saturate": lambda x: np.clip(x, 0.0, 1.0),
        "dot": lambda a, b: float(np.dot(a, b)),
        "float3": lambda *v: np.array(v, np.float64),
        "min": np.minimum,
        **{prefix + key: value for key, value in constants.items() if key.startswith("law")},
    }

    def invsssHapkeH(x, w):  # noqa: N802 - the shader's name
        scope = {**helpers, "x": x, "w": w}
        exec(hapke, scope)
        return scope["result"]

    helpers["invsssHapkeH"] = invsssHapkeH

    def run(normal, to_light):
        scope = {**helpers, "normal": np.array(normal, np.float64).view(_Vector),
                 "toLight": np.array(to_light, np.float64).view(_Vector)}
        exec(factor, scope)
        return scope["result"]

    return run


_DECLARATION = re.compile(
    r"static const (int|float|float[234]) (\w+)(?:\[(\d+)\])? = (.*?);", re.DOTALL
)
_VECTOR = re.compile(r"float([234])\(([^()]*)\)")


def parse_hlsl(text):
    """Declarations of a ``static const`` block -> {name: (type, value)}; checks that
    every array holds as many entries as its declared size and every vector as many
    components as its type says."""
    code = "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("//"))
    declarations = _DECLARATION.findall(code)
    assert _DECLARATION.sub("", code).strip() == ""  # nothing but declarations
    parsed = {}
    for kind, name, size, body in declarations:
        body = body.strip()
        if size:
            assert body.startswith("{") and body.endswith("}")
            inner = body[1:-1].strip()
            if kind == "float":
                value = [float(t) for t in inner.split(",")]
            else:
                vectors = _VECTOR.findall(inner)
                assert _VECTOR.sub("", inner).replace(",", "").strip() == ""
                value = []
                for n, components in vectors:
                    assert n == kind[-1]
                    value.append([float(t) for t in components.split(",")])
                    assert len(value[-1]) == int(n)
            assert len(value) == int(size), name
        else:
            value = int(body) if kind == "int" else float(body)
        parsed[name] = (kind, value)
    return parsed
