"""Tests of the reload commands a node process takes on standard input (no ROS)."""

import os
import threading

from mecanum_control.node_reload import (
    EitherEvent, load_command, parse_command, ReloadChannel, ReloadError)
import pytest


def test_commands_parse_and_a_load_round_trips():
    assert parse_command('unload\n') == ('unload', None)
    arguments = ['[{"label": "a b"}]', '--ros-args', '-p', 'x:=1']
    assert parse_command(load_command(arguments)) == ('load', arguments)


@pytest.mark.parametrize('line, message', [
    ('reboot', 'unknown reload command'),
    ('unload now', 'unknown reload command'),
    ('load [1, 2]', 'JSON list of strings'),
    ('load {"a": 1}', 'JSON list of strings'),
    ('load [', 'not JSON'),
])
def test_bad_commands_are_clear_errors(line, message):
    with pytest.raises(ReloadError, match=message):
        parse_command(line)


def test_a_channel_on_a_pipe_signals_unload_then_hands_over_the_load(capsys):
    read_fd, write_fd = os.pipe()
    with os.fdopen(read_fd) as reader, os.fdopen(write_fd, 'w') as writer:
        channel = ReloadChannel(reader)
        writer.write('nonsense\nunload\n')
        writer.flush()
        assert channel.unload_requested.wait(5.0)
        writer.write(load_command(['--ros-args', '-p', 'seed:=3']))
        writer.flush()
        assert channel.next_load(threading.Event()) == ['--ros-args', '-p', 'seed:=3']
        assert not channel.unload_requested.is_set()    # a new round
        assert channel.errors == ["unknown reload command 'nonsense' (unload, load ARGS)"]
        writer.close()   # the launch runner is gone: an unload without a load after it
        assert channel.unload_requested.wait(5.0)
        assert channel.next_load(threading.Event()) is None
    assert 'reload: failed: unknown reload command' in capsys.readouterr().out


def test_next_load_returns_none_when_stopped():
    read_fd, write_fd = os.pipe()
    with os.fdopen(read_fd) as reader, os.fdopen(write_fd, 'w'):
        channel = ReloadChannel(reader)
        stop = threading.Event()
        stop.set()
        assert channel.next_load(stop, poll_s=0.01) is None


def test_either_event():
    first, second = threading.Event(), threading.Event()
    assert not EitherEvent(first, second).is_set() and not EitherEvent(first, None).is_set()
    second.set()
    assert EitherEvent(first, second).is_set() and not EitherEvent(first, None).is_set()
    first.set()
    assert EitherEvent(first, None).is_set()
