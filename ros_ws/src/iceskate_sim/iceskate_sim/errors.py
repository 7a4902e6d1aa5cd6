"""The one exception type of iceskate_sim and its subclasses for input refused before anything
ran and for a run ended by a signal (what each means as an exit status: ``exit_codes``)."""

from __future__ import annotations

import signal


class SimulationError(RuntimeError):
    """Raised for every failure of the simulator: divergence, rank loss, an output that cannot
    be written, and (as ``InputRefused``) bad input such as a bad scene.

    The message names the problem (the offending key, value, coordinate or event) and, for a
    failure during a run, the simulation time, the gait mode and a summary of the state.

    :param end: how it ends a run, as ``metrics.json``'s ``end`` names it: 'failed' (the
        default), 'diverged' (the physics broke down), 'controller_failed' (a controller raised
        or answered a bad command), 'controller_timeout' (no answer in time), 'io_error' (an
        output could not be written).
    """

    def __init__(self, message: str = '', end: str = 'failed') -> None:
        super().__init__(message)
        self.end = end


class InputRefused(SimulationError):
    """Input refused before anything ran: a bad argument, value, file, scene, key or parameter,
    found where the input is checked; the message names it."""


class RunInterrupted(SimulationError):
    """A run ended from outside by a signal (SIGINT, SIGTERM, SIGHUP, ...): not a failure of
    the physics and not a fall; its outputs hold everything simulated until then.

    :param signum: the signal.
    :param t: simulation time the run reached [s] (None: it had not started).
    :param detail: what else to say (e.g. that the launching process is gone).
    :ivar exit_code: the shell's convention for a process ended by the signal, 128 + signum
        (130 for SIGINT, 143 for SIGTERM, 129 for SIGHUP).
    """

    def __init__(self, signum: int, t: float | None = None, detail: str = '') -> None:
        try:
            name = signal.Signals(signum).name
        except ValueError:
            name = f'signal {signum}'
        when = f'at t={t:.6f} s' if t is not None else 'before the simulation started'
        super().__init__(f'interrupted by {name} {when}' + (f' ({detail})' if detail else ''),
                         end='interrupted')
        self.signum, self.t = int(signum), t
        self.exit_code = 128 + int(signum)
