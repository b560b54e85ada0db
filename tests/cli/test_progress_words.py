"""The time left that ``collect``, ``campaign`` and ``train`` print is at this run's pace (work done before a resume
took no time here), and a log gets a progress line the first time, every few seconds, and the last time."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from unitac_rig.cli import output


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> list[float]:
    """The seconds ``output`` reads as ``time.monotonic()``; set ``clock[0]`` to move it."""
    now = [1000.0]
    monkeypatch.setattr(output, "time", SimpleNamespace(monotonic=lambda: now[0]))
    return now


def test_time_left_is_at_this_runs_pace_not_counting_work_before_a_resume(clock: list[float]) -> None:
    pace = output.Pace()  # a resumed collection: 40 of 91 presses were done by an earlier run
    assert pace.left_text(51) == ""  # nothing finished yet in this run
    clock[0] += 60.0
    pace.update(41)  # the first press of this run took a minute
    assert pace.left_text(91 - 41) == "about 50 min left"
    clock[0] += 30.0
    pace.update(42)  # 90 s for two presses
    assert pace.left_text(91 - 42) == "about 37 min left"
    assert pace.left_text(0) == ""  # done


def test_a_campaign_pace_counts_from_zero_presses(clock: list[float]) -> None:
    pace = output.Pace(done_before=0)
    pace.update(0)  # a session that pressed nothing says nothing about the pace
    assert pace.left_text(10) == ""
    clock[0] += 20.0
    pace.update(4)
    assert pace.left_text(6) == "about 30 s left"


def test_a_log_gets_the_first_line_one_every_few_seconds_and_the_last(clock: list[float]) -> None:
    lines = output.EveryFewSeconds(10.0)
    assert lines.due()
    clock[0] += 4.0
    assert not lines.due()
    assert lines.due(last=True)
    clock[0] += 10.0
    assert lines.due()


@pytest.mark.parametrize(
    ("seconds", "spoken"), [(45.0, "45 s"), (89.4, "89 s"), (720.0, "12 min"), (3900.0, "1 h 05 min")]
)
def test_durations_are_said_as_a_person_would(seconds: float, spoken: str) -> None:
    assert output.spoken_duration(seconds) == spoken
