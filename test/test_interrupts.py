"""Interrupts that Python cannot raise where they arrive are delivered again, not lost."""

from __future__ import annotations

import signal
import time

import pytest

from grasp_safety_filter.io.interrupts import interrupt_on_signals, SignalInterrupt


class _SignalsWhenCollected:
    """An object whose finaliser receives a signal (as a weakref callback or GC may)."""

    def __init__(self, signum: signal.Signals) -> None:
        self.signum = signum

    def __del__(self) -> None:
        signal.raise_signal(self.signum)


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_an_interrupt_raised_inside_a_finaliser_reaches_the_program(signum, capsys):
    with interrupt_on_signals():
        with pytest.raises(SignalInterrupt) as interrupt:
            _SignalsWhenCollected(signum)  # collected at once: the handler runs in __del__
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline:
                time.sleep(0.001)
    assert interrupt.value.signum == signum
    assert 'Exception ignored' not in capsys.readouterr().err


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_an_interrupt_is_held_off_an_import_and_raised_once_it_is_done(
    signum, tmp_path, monkeypatch
):
    """An extension initialising itself may turn an exception raised in it into ImportError.

    The module below does what numpy's C core does when interrupted while it imports
    ``datetime``; the interrupt must reach the program after the import, not inside it.
    """
    name = f'imports_while_signalled_{signum.name.lower()}'
    (tmp_path / f'{name}.py').write_text(
        'import signal, time\n'
        'try:\n'
        f'    signal.raise_signal({int(signum)})\n'
        '    time.sleep(0.2)\n'
        'except BaseException as error:\n'
        '    raise ImportError("the C-extensions failed to import") from error\n'
        'COMPLETE = True\n'
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    with interrupt_on_signals():
        with pytest.raises(SignalInterrupt) as interrupt:
            __import__(name)
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline:
                time.sleep(0.001)
    assert interrupt.value.signum == signum
    assert __import__(name).COMPLETE


def test_a_signal_held_off_an_import_at_the_end_of_the_block_is_raised_as_it_ends(
    tmp_path, monkeypatch
):
    """The signal is sent again after a delay: the block may be over by then.

    Left to the restored handlers it would end the process (SIGTERM) or raise anywhere
    (SIGINT); it is raised as the block ends instead, and never reaches them.
    """
    (tmp_path / 'signalled_at_the_end.py').write_text(
        'import signal\nsignal.raise_signal(signal.SIGTERM)\n'
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    received: list[int] = []
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: received.append(signum))
    try:
        with pytest.raises(SignalInterrupt) as interrupt:
            with interrupt_on_signals():
                __import__('signalled_at_the_end')  # the block ends at once
        time.sleep(0.1)  # past the re-sending delay
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert interrupt.value.signum == signal.SIGTERM
    assert received == []


def _raised_after(call, signum: signal.Signals) -> list:
    """Call ``call`` in a block; return what it returned, asserting ``signum`` came after."""
    returned = []
    with interrupt_on_signals():
        with pytest.raises(SignalInterrupt) as interrupt:
            returned.append(call())
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline:
                time.sleep(0.001)
    assert interrupt.value.signum == signum
    return returned


def test_an_interrupt_is_held_off_numbas_callback_and_raised_after_it(tmp_path, monkeypatch):
    """Numba's compiled code calls ``_numba_unpickle`` from C: an exception there is lost.

    It becomes ``SystemError``; the module below stands in for numba's (a package named
    ``numba``, the same file and function name) and is signalled inside it, as a Ctrl-C
    may land there.
    """
    import importlib.util
    import sys
    import types

    package = tmp_path / 'numba'
    serialize = package / 'core' / 'serialize.py'
    serialize.parent.mkdir(parents=True)
    (package / '__init__.py').write_text('')
    serialize.write_text(
        'import signal, time\n'
        'def _numba_unpickle(address, bytedata, hashed):\n'
        '    signal.raise_signal(signal.SIGINT)\n'
        '    time.sleep(0.05)\n'
        '    return "unpickled"\n'
    )
    stand_in = types.ModuleType('numba')
    stand_in.__file__ = str(package / '__init__.py')
    monkeypatch.setitem(sys.modules, 'numba', stand_in)
    spec = importlib.util.spec_from_file_location('stand_in_serialize', serialize)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert _raised_after(lambda: module._numba_unpickle(0, b'', b''), signal.SIGINT) == [
        'unpickled'
    ]


def test_an_interrupt_is_held_off_numbas_compiler_and_raised_after_it():
    """A signal while numba compiles or loads a kernel reaches the program once it is done.

    Raised inside numba's typing, an interrupt can leave its registries half-loaded: every
    later compile or cache load in the process then fails (``generator raised
    StopIteration``). Here the signal arrives while numba types a call, from inside an
    overload that numba's compiler calls; the kernel must compile and run, and numba must
    still compile afterwards.
    """
    import numba
    from numba.extending import overload

    def signalled() -> int:
        raise NotImplementedError('only compiled')

    @overload(signalled)
    def _typed_while_signalled():
        signal.raise_signal(signal.SIGTERM)
        time.sleep(0.05)
        return lambda: 7

    @numba.njit(cache=False)
    def kernel() -> int:
        return signalled() + 1

    assert _raised_after(kernel, signal.SIGTERM) == [8]

    @numba.njit(cache=False)
    def afterwards(x: float) -> float:
        return 2.0 * x

    assert afterwards(1.5) == 3.0
