"""The command line and the persistent compilation cache: ``--no-cache`` on every
command, the cache switched on or off by it, and the progress line saying how long
compiling took, once."""

from __future__ import annotations

import io
import os

import jax
import jax.numpy as jnp
import pytest

from invsss.cli import build_parser, main
from invsss.runtime.compile_cache import enable_compile_cache


@pytest.mark.parametrize("command", [
    ["render", "--image", "i.exr", "--depth", "d.exr", "--mask", "m.png", "--params", "p.json",
     "--out", "o.exr"],
    ["fit", "--source", "s.exr", "--target", "t.exr", "--depth", "d.exr", "--mask", "m.png",
     "--out", "dir"],
    ["sweep", "e.toml", "--out", "dir"],
])
def test_cli_no_cache_flag(command):
    parser = build_parser()
    assert parser.parse_args(command).no_cache is False
    assert parser.parse_args(command + ["--no-cache"]).no_cache is True


def test_cli_switches_the_cache_on_or_off(tmp_path, monkeypatch):
    session = os.environ["INVSSS_CACHE_DIR"]
    monkeypatch.setenv("INVSSS_CACHE_DIR", str(tmp_path / "cli"))
    missing = ["render", "--image", str(tmp_path / "none.exr"), "--depth", "d.exr", "--mask",
               "m.png", "--params", "p.json", "--out", str(tmp_path / "o.exr")]
    # The command fails on its missing input, after the cache was set up.
    assert main(missing + ["--no-cache"]) == 2
    assert os.environ["INVSSS_NO_CACHE"] == "1"
    assert not (tmp_path / "cli").exists()
    del os.environ["INVSSS_NO_CACHE"]
    assert main(missing) == 2
    assert jax.config.jax_compilation_cache_dir == str(tmp_path / "cli")
    assert (tmp_path / "cli").is_dir()
    enable_compile_cache(session)  # later tests compile into the session's directory again


def test_fit_progress_says_how_long_compiling_took_once():
    from invsss.cli.progress import ProgressLine

    stream = io.StringIO()
    progress = ProgressLine(stream, lambda: 3.14)
    progress(1, 1e-3)
    progress(2, 5e-4)
    lines = stream.getvalue().splitlines()
    assert lines == ["fit: compiling ... 3.1 s", "fit: iter 1  loss 1.000e-03"]
    warm = io.StringIO()
    ProgressLine(warm, lambda: 0.01)(1, 1e-3)
    assert warm.getvalue().splitlines() == ["fit: compiled code loaded from the cache", "fit: iter 1  loss 1.000e-03"]
    # The first warm run tries the entries in a child process: its pause is explained.
    first_warm = io.StringIO()
    ProgressLine(first_warm, lambda: 0.01, lambda: 6.25)(1, 1e-3)
    assert first_warm.getvalue().splitlines()[0] == (
        "fit: compiled code loaded from the cache (its first use here: tried in a separate process first, 6.2 s)")
    verified = io.StringIO()
    ProgressLine(verified, lambda: 0.01, lambda: 0.0)(1, 1e-3)
    assert verified.getvalue().splitlines()[0] == "fit: compiled code loaded from the cache"


def test_compile_seconds_counts_a_new_compilation():
    from invsss.cli.progress import compile_seconds

    before = compile_seconds()
    jax.jit(lambda x: jnp.sin(x) * 3.0 + jnp.cos(x) ** 2)(jnp.arange(7.0)).block_until_ready()
    assert compile_seconds() > before
