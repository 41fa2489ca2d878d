"""A hostile or unlucky user: planted links, pathological files, huge numbers, stuck workers,
signals at awkward moments.

Every test drives the real CLI in a subprocess (the helpers of ``tests/test_robustness.py``)
and checks the exit code, that stderr is at most a few lines without a traceback, and that
files outside the output path are left as they were. Bad input is exit 2 with one line naming
the file and the field, and what would be valid.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from pickplace.errors import OutputError
from pickplace.outfile import OutputFile
from tests.test_robustness import clean_stderr, cli, complete_rrd, finish, one_json

PRECIOUS = "precious\n"


# ---------------------------------------------------------------------------- the lock file


@pytest.mark.parametrize("kind", ["symlink", "hardlink"])
def test_a_planted_lock_link_is_refused_and_what_it_points_at_is_untouched(
    tmp_path: Path, kind: str
) -> None:
    precious = tmp_path / "v.txt"
    precious.write_text(PRECIOUS)
    lock = tmp_path / ".v.rrd.lock"
    if kind == "symlink":
        lock.symlink_to("v.txt")
    else:
        os.link(precious, lock)
    code, out, err = finish(cli("run", "--record", str(tmp_path / "v.rrd"), cwd=tmp_path), 60)
    assert code == 2
    (line,) = clean_stderr(err)
    assert "--record" in line and ".v.rrd.lock" in line
    assert ("symbolic link" if kind == "symlink" else "hard links") in line
    assert out == ""
    assert precious.read_text() == PRECIOUS
    assert sorted(p.name for p in tmp_path.iterdir()) == [".v.rrd.lock", "v.txt"]


def test_a_lock_link_planted_after_the_checks_is_not_followed(tmp_path: Path) -> None:
    precious = tmp_path / "v.txt"
    precious.write_text(PRECIOUS)
    (tmp_path / ".v.rrd.lock").symlink_to("v.txt")
    output = OutputFile(tmp_path / "v.rrd")
    with pytest.raises(OutputError, match="symbolic link"):
        output.open()
    assert precious.read_text() == PRECIOUS
    assert not (tmp_path / "v.rrd").exists()


def test_a_record_name_near_the_file_system_limit_is_written(tmp_path: Path) -> None:
    name = "a" * 240 + ".rrd"  # legal (244 bytes), but ".<name>.<pid>-<hex>.tmp" would not be
    code, out, err = finish(cli("run", "--record", name, "--json", cwd=tmp_path), 120)
    assert code == 0, err
    assert one_json(out)["recording"] == name
    complete_rrd(tmp_path / name)
    assert [p.name for p in tmp_path.iterdir()] == [name]  # no lock or temporary file left


def test_a_record_name_beyond_the_file_system_limit_is_bad_input(tmp_path: Path) -> None:
    code, _, err = finish(cli("run", "--record", "b" * 252 + ".rrd", cwd=tmp_path), 60)
    assert code == 2
    (line,) = clean_stderr(err)
    assert "--record" in line and "256 bytes long" in line and "at most 255" in line
    assert list(tmp_path.iterdir()) == []
