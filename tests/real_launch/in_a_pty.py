"""
Run a command in a pseudo-terminal of its own (a launch-prefix standing in for xterm).

tests/test_real_launch.py starts teleop.launch.py with ``terminal:=`` this script: the
keyboard node needs a terminal, and CI has no display for xterm. SIGINT and SIGTERM
are passed on to the command (launch stops a process with them); what it writes to
the terminal is copied to standard output. Exit code: the command's.
"""

import os
import pty
import signal
import sys


def main(command) -> int:
    """Run command in a new pty until it exits; return its exit code."""
    pid, terminal = pty.fork()
    if pid == 0:
        os.execvp(command[0], command)
    for number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(number, lambda signum, _frame: os.kill(pid, signum))
    while True:
        try:
            data = os.read(terminal, 4096)
        except InterruptedError:
            continue
        except OSError:      # EIO: the command closed its terminal (it exited)
            break
        if not data:
            break
        os.write(sys.stdout.fileno(), data)
    while True:
        try:
            return os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])
        except InterruptedError:
            continue


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
