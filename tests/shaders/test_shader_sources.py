"""The reference shaders' sources (invsss.shaders): the files of one model."""

from __future__ import annotations

import pytest

from invsss import InvalidInputError
from invsss.shaders import SHADER_FILES, shader_sources

SHADER = "invsss_burley.hlsl"


def test_shader_sources_of_one_model():
    assert list(shader_sources(model="burley")) == ["invsss_common.hlsl", SHADER]
    assert list(shader_sources(model="sog")) == ["invsss_common.hlsl", "invsss_seven_tap.hlsl", "invsss_sog.hlsl"]
    assert list(shader_sources()) == list(SHADER_FILES) and SHADER in SHADER_FILES
    named = shader_sources("skin.hlsl", model="burley")[SHADER]
    assert '#include "skin.hlsl"' in named and '#include "invsss_constants.hlsl"' not in named
    with pytest.raises(InvalidInputError, match=r"^model: expected one of .*got 'blur'$"):
        shader_sources(model="blur")
