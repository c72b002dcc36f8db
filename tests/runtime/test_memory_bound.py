"""A process holds a bounded number of executables, and can let go of all of them.

XLA maps each executable's machine code into the process (about 41 memory maps
apiece on a CPU) until the executable is freed, and Linux bounds a process's maps
(vm.max_map_count, 65530 by default): a process that keeps every executable it
compiles aborts in LLVM once it has compiled enough of them.
"""

from __future__ import annotations

import gc

import jax.numpy as jnp

from invsss.runtime.executable_cache import MAX_IN_MEMORY, persistent_jit, release_compiled
from tests.runtime._executables import cache_dir  # noqa: F401 (fixture)


def _maps() -> int:
    with open("/proc/self/maps") as maps:
        return sum(1 for _ in maps)


def test_a_function_keeps_its_most_recently_used_executables_and_reloads_older_ones(cache_dir):  # noqa: F811
    folder = cache_dir() / "executables"

    @persistent_jit
    def shifted(x):
        return jnp.cumsum(jnp.sin(x), axis=0) + 1.0

    shifted(jnp.ones((3, 3)))
    for entry in folder.glob("*.executable"):
        entry.unlink()  # from here only memory holds it: leaving memory would mean compiling again
    others = range(4, MAX_IN_MEMORY + 8)
    for n in others:
        shifted(jnp.ones((n, 3)))
        shifted(jnp.ones((3, 3)))  # used after every other: never the least recently used
    assert shifted.traces == 1 + len(others)
    assert len(shifted._memory) == MAX_IN_MEMORY
    # The least recently used left memory but not the disk: loaded again, not traced again.
    assert shifted(jnp.ones((4, 3))).shape == (4, 3)
    assert shifted.traces == 1 + len(others)


def test_release_compiled_gives_the_code_memory_back(cache_dir):  # noqa: F811
    cache_dir()
    funs = []
    for k in range(40):
        def fun(x, k=k):
            for i in range(4):
                x = jnp.sin(x * (i + k + 1)) + jnp.cumsum(x, axis=0) * 1e-3
            return x
        fun.__qualname__ = f"fun_{k}"  # a distinct disk entry for each
        funs.append(persistent_jit(fun))
    gc.collect()
    before = _maps()
    for f in funs:
        f(jnp.ones((8, 8)))
    held = _maps() - before
    release_compiled()
    gc.collect()
    left = _maps() - before
    # Compiled code holds memory maps until released; afterwards most are gone.
    assert held > 200
    assert left < held / 4
    assert funs[0](jnp.ones((8, 8))).shape == (8, 8)   # and the functions still work
