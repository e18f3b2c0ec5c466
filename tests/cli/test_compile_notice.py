"""Issue 53: a first run says that kernels compile, and keeps saying so while a long compile goes on."""

from __future__ import annotations

import io

from numba.core import event

from porecad import first_run


class _Dispatcher:
    def __init__(self, module):
        def f():
            pass
        f.__module__ = module
        self.py_func = f


def _compile(module):
    event.start_event("numba:compile", data={"dispatcher": _Dispatcher(module)})
    event.end_event("numba:compile", data={"dispatcher": _Dispatcher(module)})


def test_notice_once_then_while_compiling(monkeypatch):
    monkeypatch.setattr(first_run, "_noticed", False)
    clock = [100.0]
    monkeypatch.setattr("time.monotonic", lambda: clock[0])
    out = io.StringIO()
    listener = first_run.install_notice(out)
    try:
        _compile("numpy.something")          # not porecad's: nothing said
        assert out.getvalue() == ""
        _compile("porecad.analysis._nearest_kernel")
        clock[0] += 1.0
        _compile("porecad.analysis._render_kernel")       # soon after: nothing more
        clock[0] += first_run.STILL_COMPILING_S + 5
        _compile("porecad.simulate.voxel_fe")
    finally:
        event.unregister("numba:compile", listener)
    lines = out.getvalue().splitlines()
    assert len(lines) == 2
    assert lines[0].startswith("porecad: compiling numerical kernels (first run after an install")
    assert lines[1].startswith("porecad: still compiling numerical kernels (21 s so far")
