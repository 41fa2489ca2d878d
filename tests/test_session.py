"""Ending a session: every process of it, however deep and wherever reparented, and no other."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from pickplace.sweep.session import end_session, members

pytestmark = pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc")

# A leader that starts a grandchild in a process group of its own (as Ray's raylet does with
# its workers), prints both ids, and sleeps.
TREE = """
import os, subprocess, sys, time
child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"],
                         process_group=0)
print(os.getpid(), child.pid, flush=True)
time.sleep(600)
"""


def test_end_session_kills_every_member_and_spares_others() -> None:
    if sys.version_info < (3, 11):
        pytest.skip("Popen(process_group=) needs Python 3.11")
    bystander = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    leader = subprocess.Popen(
        [sys.executable, "-c", TREE], stdout=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        assert leader.stdout is not None
        lead, grandchild = (int(v) for v in leader.stdout.readline().split())
        assert sorted(members(leader.pid)) == sorted([lead, grandchild])
        t0 = time.monotonic()
        assert end_session(leader.pid) == []
        assert time.monotonic() - t0 < 2.0
        assert members(leader.pid) == []
        assert leader.wait(5) == -9
        assert not Path(f"/proc/{grandchild}/cmdline").exists() or (
            Path(f"/proc/{grandchild}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
        )
        assert bystander.poll() is None
    finally:
        bystander.kill()
        bystander.wait()
        leader.kill()
        leader.wait()


def test_a_session_without_processes_has_no_members() -> None:
    assert members(2**22 + 12345) == []  # above the kernel's largest process id
    assert end_session(2**22 + 12345, 0.1) == []
