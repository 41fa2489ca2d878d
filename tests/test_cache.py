"""The disk cache: JSON values kept atomically, unreadable ones read as absent, and the home
posture a second process reads instead of planning again."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from pickplace import cache
from pickplace.sim import loader


@pytest.fixture
def cache_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    folder = tmp_path / "cache"
    monkeypatch.setenv(cache.CACHE_ENV, str(folder))
    return folder


def test_a_value_comes_back_as_written_and_a_broken_file_reads_as_absent(
    cache_folder: Path,
) -> None:
    value = {"q": [0.1, -2.5e-17, 1 / 3], "name": "x"}
    cache.write_json("v.json", value)
    assert cache.read_json("v.json") == value  # floats bit for bit
    assert [p.name for p in cache_folder.iterdir()] == ["v.json"]  # no temporary file left
    (cache_folder / "v.json").write_text('{"q": [0.1,')
    assert cache.read_json("v.json") is None
    assert cache.read_json("absent.json") is None


def test_a_folder_that_cannot_be_written_is_skipped_silently(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv(cache.CACHE_ENV, str(blocker / "cache"))
    cache.write_json("v.json", [1])  # no exception
    assert cache.read_json("v.json") is None


def test_the_cache_folder_follows_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(cache.CACHE_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", "/somewhere")
    assert cache.cache_dir() == Path("/somewhere/pickplace")
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert cache.cache_dir() == Path.home() / ".cache" / "pickplace"


def test_source_digest_changes_with_the_code(tmp_path: Path) -> None:
    a = cache.source_digest(["cache.py"])
    assert a == cache.source_digest(["cache.py"])
    assert a != cache.source_digest(["errors.py"])


@pytest.mark.slow
def test_a_second_process_reads_the_chosen_home_instead_of_planning(
    cache_folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    robot = "menagerie-iiwa14-2f85"  # its description gives no home: IK candidates are ranked
    calls: list[int] = []
    choose = loader.choose_home

    def counting(*args: object, **kwargs: object) -> np.ndarray:
        calls.append(1)
        return choose(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(loader, "choose_home", counting)
    loader.clear_scene_cache()
    first = loader.load_scene(robot=robot)
    assert len(first.robot.home_candidates) > 1 and calls == [1]
    (home_file,) = cache_folder.glob("home-*.json")
    loader.clear_scene_cache()  # as a new process finds it: nothing in memory
    second = loader.load_scene(robot=robot)
    assert calls == [1]  # read, not planned
    np.testing.assert_array_equal(second.robot.q_home, first.robot.q_home)
    # A cached posture that is not one of the candidates is not trusted: planned again.
    home_file.write_text("[0.0, 0.0]")
    loader.clear_scene_cache()
    third = loader.load_scene(robot=robot)
    assert calls == [1, 1]
    np.testing.assert_array_equal(third.robot.q_home, first.robot.q_home)
    loader.clear_scene_cache()
    assert os.path.exists(home_file)
