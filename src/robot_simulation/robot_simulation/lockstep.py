"""
Lockstep: when the simulator may step simulated time on (pure: no rclpy, no I/O).

PX4's SITL lockstep in this workspace's terms. The simulator publishes /clock at the
start of each period, then steps the physics through the period only once the stack
has answered that /clock:

- the board: a MOTOR_EFFORTS frame came in on the serial line after the /clock was
  published (hardware_interface sends velocity_controller's efforts for the period);
- every participant, i.e. every process of the stack on simulated time: its
  ``/clock_ack`` (std_msgs/Header: stamp = the /clock it took, frame_id = its name)
  says it has taken that /clock and done the work it starts (mecanum_control
  node_main.ClockAnswer: the messages before it, the timers it made due and the
  callbacks they set off within the process).

Every participant also says it is alive once a second of wall time on ``/clock_alive``
(std_msgs/Header, frame_id = its name; node_main.ClockAnswer sends it from a thread of
its own), also while one of its callbacks runs for long (a first JIT compile, a loop
closure on a loaded machine): such a part is waited for, up to ``give_up_s``.

A stalled stack therefore stalls simulated time instead of losing it. A part silent for
``timeout_s`` of wall time since the /clock it should answer, and not alive either, is
*gone* (a killed or frozen process, which the launch runner restarts; a part busy with
one /clock for ``give_up_s`` is gone too): it holds time back no longer, and
while any part is gone, or before the board has answered at all (the stack is still
starting), the simulation runs at real time at most. A gone part that answers again
takes part again. A part known to be down (:meth:`Lockstep.down`: the scenario runner
froze or killed it) is gone at once: a dead or stopped process holds no simulated time
back, so the stack's watchdogs see its silence as a real robot's would; until it answers
again the board is not waited for either (the commands may stop with it). The board
silent for ``give_up_s`` of wall time ends the run with :class:`LockstepError`, naming
it.

Times: ``sim_s`` simulated seconds, ``wall_s`` seconds of a monotonic wall clock.
"""

from dataclasses import dataclass
import math
from typing import Dict, List, Optional

#: The topic (std_msgs/String: a process's /clock_ack name) on which the scenario runner
#: names a process it has just frozen or killed (the simulator calls Lockstep.down).
PROCESS_DOWN_TOPIC = 'simulator/process_down'
#: The board's name in messages.
BOARD = 'the board (MOTOR_EFFORTS from hardware_interface)'


class LockstepError(RuntimeError):
    """The stack stopped answering for good; the message names the silent part."""


@dataclass(frozen=True)
class LockstepConfig:
    """Wall-clock limits of the lockstep, in seconds."""

    #: A part that has not answered a /clock for this long is gone (no longer awaited).
    #: Long enough for a live part busy with a long callback on a loaded machine (a
    #: SLAM loop closure took over 2 s beside two other simulations on 2 cores).
    timeout_s: float = 10.0
    #: The board without a command for this long ends the run.
    give_up_s: float = 60.0

    def __post_init__(self):
        """Check the limits: positive and finite, give_up_s not below timeout_s."""
        for name in ('timeout_s', 'give_up_s'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ValueError(f'lockstep {name} must be a finite number > 0 s, got {value!r}')
        if self.give_up_s < self.timeout_s:
            raise ValueError(f'lockstep give_up_s ({self.give_up_s} s) must not be below '
                             f'timeout_s ({self.timeout_s} s)')


@dataclass
class _Part:
    """What lockstep knows of one answering part."""

    answered_sim_s: float = -math.inf
    answered_wall_s: float = -math.inf
    alive_wall_s: float = -math.inf
    gone: bool = False
    down: bool = False     # said down (Lockstep.down), until it answers again


class Lockstep:
    """
    The simulator's gate between the stack's answers and simulated time.

    Call :meth:`published` after each /clock, feed in the answers, step on while
    :meth:`waiting_for` is empty.

    :meth:`events` returns (and forgets) what happened worth a log line: parts gone and
    back.
    """

    def __init__(self, config: LockstepConfig = LockstepConfig()):
        self.config = config
        self.board_commands = 0
        self._board = _Part()
        self._board_engaged = False
        self._board_count_at_clock = 0
        self._participants: Dict[str, _Part] = {}
        self._clock_sim_s = -math.inf
        self._clock_wall_s = -math.inf
        self._events: List[str] = []

    # --- inputs ------------------------------------------------------------------------
    def published(self, sim_s: float, wall_s: float) -> None:
        """Note a /clock of sim_s published at wall_s: the stack's answers are now due."""
        self._clock_sim_s, self._clock_wall_s = sim_s, wall_s
        self._board_count_at_clock = self.board_commands

    def board_command(self, wall_s: float) -> None:
        """Note a MOTOR_EFFORTS frame that came in at wall_s."""
        self.board_commands += 1
        board = self._board
        if board.gone:
            self._events.append(f'lockstep: {BOARD} answers again')
        elif not self._board_engaged:
            self._events.append(f'lockstep: {BOARD} answers: simulated time now waits '
                                'for the stack')
        self._board_engaged = True
        board.gone = False
        board.answered_sim_s, board.answered_wall_s = self._clock_sim_s, wall_s

    def ack(self, name: str, sim_s: float, wall_s: float) -> None:
        """Note participant name's /clock_ack at wall_s: it took the /clock of sim_s."""
        part = self._participants.get(name)
        if part is None:
            part = self._participants[name] = _Part()
            self._events.append(f'lockstep: {name} takes part')
        elif part.gone:
            self._events.append(f'lockstep: {name} answers again')
        part.gone = part.down = False
        part.answered_sim_s = max(part.answered_sim_s, sim_s)
        part.answered_wall_s = wall_s

    def alive(self, name: str, wall_s: float) -> None:
        """Note participant name's /clock_alive at wall_s (ignored before it takes part)."""
        part = self._participants.get(name)
        if part is not None:
            part.alive_wall_s = max(part.alive_wall_s, wall_s)

    def down(self, name: str, why: str) -> None:
        """
        Take part name as gone now: its process was stopped or killed (why says how).

        Simulated time no longer waits for it (at real time at most, as for any gone
        part) until it answers again. Nor for the board meanwhile: its commands come
        through the stack (velocity_controller's efforts, sent by hardware_interface),
        which may stop until time has run on (hardware_interface's keep-alive is timed
        on simulated time; the board's watchdog too, as on a robot); it is still
        listened to. A name never heard is ignored.
        """
        part = self._participants.get(name)
        if part is None or part.gone:
            return
        part.gone = part.down = True
        self._events.append(f'lockstep: {name} is down ({why}): going on without it, at '
                            'real time at most')
        if self._board_engaged and not self._board.gone:
            self._events.append(f'lockstep: not waiting for {BOARD} while {name} is down')

    # --- outputs -----------------------------------------------------------------------
    def waiting_for(self, wall_s: float) -> List[str]:
        """
        Return the parts that still owe an answer to the last /clock (empty: step on).

        A part that has owed it for timeout_s is declared gone here (and no longer
        listed). Raises LockstepError when the board has been silent for give_up_s.
        """
        waited_s = wall_s - self._clock_wall_s
        missing = []
        if self._board_engaged:
            board = self._board
            if board.gone or self._board_excused():
                silent_s = wall_s - board.answered_wall_s
                if silent_s >= self.config.give_up_s:
                    raise LockstepError(
                        f'lockstep: {BOARD} has not answered for {silent_s:.0f} s of wall '
                        f'time (since simulated time {board.answered_sim_s:.2f} s): the '
                        'stack is not running; ending the simulation')
            elif self.board_commands == self._board_count_at_clock:
                self._owing(BOARD, board, waited_s, waited_s, missing)
        for name, part in self._participants.items():
            if not part.gone and part.answered_sim_s < self._clock_sim_s - 1e-9:
                silent_s = min(waited_s, wall_s - part.alive_wall_s)
                self._owing(name, part, waited_s, silent_s, missing)
        return missing

    def _owing(self, name: str, part: _Part, waited_s: float, silent_s: float,
               missing: List[str]) -> None:
        """Take a part that owes the last /clock: gone when silent or busy too long."""
        if silent_s >= self.config.timeout_s:
            why = f'has not answered /clock {self._clock_sim_s:.2f} s for {waited_s:.1f} s'
        elif waited_s >= self.config.give_up_s:
            why = (f'has been busy with /clock {self._clock_sim_s:.2f} s for {waited_s:.1f} s '
                   '(alive, but not answering)')
        else:
            missing.append(name)
            return
        part.gone = True
        self._events.append(f'lockstep: {name} {why}: going on without it, at real time '
                            'at most')

    @property
    def free_running(self) -> bool:
        """Tell whether time runs unlocked: no board answer yet, or a part gone."""
        return (not self._board_engaged or self._board.gone
                or any(part.gone for part in self._participants.values()))

    def _board_excused(self) -> bool:
        """Tell whether a part said down is still gone (the board is not awaited)."""
        return any(part.down for part in self._participants.values())

    @property
    def participants(self) -> List[str]:
        """Return the participants heard so far (gone or not), sorted."""
        return sorted(self._participants)

    def events(self) -> List[str]:
        """Return the log-worthy events since the last call, oldest first."""
        events, self._events = self._events, []
        return events

    def last_answer_sim_s(self, name: Optional[str] = None) -> float:
        """Return the last /clock a participant (default: the board) answered, in sim s."""
        part = self._board if name is None else self._participants[name]
        return part.answered_sim_s
