"""The suite's warm ``twin`` (tests/cli_server.py) is the command line a user runs: the same exit
code, standard output and error as a new interpreter for a verb that works, one that refuses its
input and ``--version``; the caller's environment; a call past its timeout raises TimeoutExpired
and is killed. (The caller's PYTHONPATH: the plug-in tests load their modules from it.)"""

from __future__ import annotations

import os
import subprocess
import time

import cli_server
import pytest
from conftest import REPO, TWIN


def _fresh(args, env):
    return subprocess.run([*TWIN, *args], cwd=REPO, env=env, capture_output=True, text=True)


@pytest.mark.parametrize("args", [
    ["export-model", "quick", "-o", "{tmp}/axis.xml"],
    ["simulate", "quick", "-o", "{tmp}/out", "--set", "phase1.capture_s=-1"],
    ["--version"],
], ids=["works", "refused", "version"])
def test_forked_call_equals_a_new_interpreter(args, tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO), COLUMNS="150")
    done = []
    for way, run in (("fresh", _fresh), ("forked", lambda a, e: cli_server.call(a, e, REPO))):
        d = tmp_path / way
        d.mkdir()
        proc = run([a.format(tmp=d) for a in args], env)
        done.append((proc.returncode, proc.stdout.replace(str(d), "TMP"), proc.stderr.replace(str(d), "TMP")))
    assert done[0] == done[1]
    assert (done[0][0] == 0) == (args[0] != "simulate")


def test_forked_call_takes_the_callers_environment(tmp_path):
    """An environment variable the verb reads is the caller's: TWIN_WORKERS=0 is refused naming it,
    as by a new interpreter. (The caller's PYTHONPATH: the plug-in tests load their modules from
    it, tests/test_plugins.py and tests/test_plugin_kinds.py.)"""
    env = dict(os.environ, PYTHONPATH=str(REPO), TWIN_WORKERS="0")
    args = ["simulate", "quick", "-o", str(tmp_path / "o")]
    forked, fresh = cli_server.call(args, env, REPO), _fresh(args, env)
    assert forked.returncode == fresh.returncode == 2
    assert "TWIN_WORKERS" in forked.stderr and forked.stderr == fresh.stderr


def test_timeout_kills_the_call(tmp_path):
    """A call past its timeout raises TimeoutExpired, as subprocess.run does, and its process is
    gone (killed with its process group, and reaped)."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    with pytest.raises(subprocess.TimeoutExpired):
        cli_server.call(["simulate", "paper-rtf", "-o", str(tmp_path / "long"), "--workers", "1"], env, REPO, timeout=5)
    pid = cli_server._SERVER.last_pid
    for _ in range(100):
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        pytest.fail(f"the timed-out call (pid {pid}) is still running")
