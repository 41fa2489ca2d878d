"""A recording file is put in place only once it reads back complete.

Both a run's recording (:class:`~pickplace.record.recording.Recorder`) and a sweep's
(:mod:`pickplace.sweep.recording`) are written to a temporary file beside their path
(:class:`~pickplace.outfile.OutputFile`), read back here, and renamed onto the path only then:
the path holds either a complete recording or what was there before.
"""

from __future__ import annotations

import warnings
from pathlib import Path

from pickplace.errors import OutputError
from pickplace.outfile import OutputFile


def read_back_problem(path: Path, required_entity: str) -> str | None:
    """None if the ``.rrd`` at ``path`` reads back with its footer and ``required_entity``
    (e.g. ``"summary"``, logged last), else what is wrong. Reads the footer's manifest, not
    the data: milliseconds."""
    from rerun.chunk import RrdReader  # rerun is imported only when recording

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "no footer" is reported below instead
            entities = RrdReader(path).store().schema().entity_paths()
    except (RuntimeError, OSError, ValueError) as exc:
        return f"the file does not read back ({' '.join(str(exc).split())[:200]})"
    if f"/{required_entity}" not in entities:
        return f"the file lacks the {required_entity}"
    return None


def commit_bytes(output: OutputFile, data: bytes, required_entity: str, what: str) -> Path:
    """Write an encoded recording ``data`` to ``output``'s temporary file, check that it reads
    back with ``required_entity`` and put it in place.

    Args:
        output: The output file (opened here if it is not yet).
        data: The ``.rrd`` bytes.
        required_entity: An entity the file must hold (logged last).
        what: What the file is, for messages (``"the sweep recording"``).

    Raises:
        OutputError: The file could not be written or is incomplete (the temporary file is
            deleted, an older file at the path is unchanged).
    """
    temp = output.open()
    try:
        with open(temp, "wb") as f:
            f.write(data)
    except OSError as exc:
        output.discard()
        raise OutputError(
            f"cannot write {what} '{output.path}': {exc.strerror or exc}; "
            "an older file there is unchanged"
        ) from None
    problem = read_back_problem(temp, required_entity)
    if problem is not None:
        output.discard()
        raise OutputError(f"cannot write {what} '{output.path}': {problem}") from None
    output.commit()
    return output.path


__all__ = ["commit_bytes", "read_back_problem"]
