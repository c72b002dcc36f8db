"""Bit-for-bit reruns on the CPU: XLA's scheduler that orders operations for concurrency off.

With that scheduler (XLA's default on the CPU), the solver's compiled step is
not deterministic: from identical inputs, 7, 6 and 3 of 2500 calls of the step
on data_synthetic/pt_face_940 returned another trial point, also with one XLA
thread, XNNPACK off or ``OPENBLAS_NUM_THREADS=1``, while the loss and the
Jacobian alone were the same in 3000 and 2500 calls. A fit that meets such a
step takes another path; on that ill-conditioned pair about 1 fit in 8 ended
elsewhere, by up to 0.005 standard errors. With the scheduler off, 2500 and 5000
calls were all the same, at the same speed, and 12 of 12 command-line fits of
that pair had the same loss at every step (2 of 12 had differed without it).

XLA reads the setting from ``XLA_FLAGS`` once, when JAX starts its CPU backend
(on the first computation); a compile option passed to one function did not
change the result. So it has to be set before anything runs: the command line
does so first thing, and a script calls :func:`use_deterministic_scheduler`
before its first JAX computation.
"""

from __future__ import annotations

import os

__all__ = ["SCHEDULER_FLAG", "use_deterministic_scheduler"]

#: The ``XLA_FLAGS`` entry that switches the concurrency-optimised scheduler off.
SCHEDULER_FLAG = "--xla_cpu_enable_concurrency_optimized_scheduler=false"


def _backend_started() -> bool:
    try:
        from jax._src import xla_bridge

        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):  # a JAX without the query: assume not yet
        return False


def use_deterministic_scheduler() -> bool:
    """Add :data:`SCHEDULER_FLAG` to ``XLA_FLAGS`` if JAX's backend has not started.

    Returns whether the flag is in effect for this process: ``False`` when JAX
    has already computed something, even only made an array (an
    :class:`invsss.SSSParams` holds JAX arrays), for then XLA has read its flags and the
    environment is left as it is) or when ``XLA_FLAGS`` sets the option
    otherwise. A value the user gave for the option is kept. Child processes
    started afterwards (a sweep's workers) inherit the environment.

    Examples
    --------
    >>> import os
    >>> from invsss.runtime.determinism import use_deterministic_scheduler, SCHEDULER_FLAG
    >>> use_deterministic_scheduler() == (SCHEDULER_FLAG in os.environ.get("XLA_FLAGS", ""))
    True
    """
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_enable_concurrency_optimized_scheduler" in flags:
        return SCHEDULER_FLAG in flags.split()
    if _backend_started():
        return False
    os.environ["XLA_FLAGS"] = f"{flags} {SCHEDULER_FLAG}".strip()
    return True
