"""integration.duration: task lengths in time, rounded up to whole periods per frequency,
as an alternative to integration.periods (with discard_duration for discard_periods)."""

import math

import pytest

from sdmpi.config import JobError, canonical_text, enumerate_tasks, parse_job

OMEGAS = "[shear]\nomega = [1.0, 6.283185307179586, 100.0]\n"


def problems(text, overrides=()):
    with pytest.raises(JobError) as info:
        parse_job(text, overrides)
    return [str(p) for p in info.value.problems]


def test_duration_rounds_up_to_whole_periods_at_each_frequency():
    job = parse_job(OMEGAS + "[integration]\nduration = 10.0\ndiscard_duration = 2.0\n"
                    "steps_per_period = 40\n")
    # ceil(10 w / 2 pi): w = 1 -> 1.59 -> 2; w = 2 pi -> exactly 10 (not 11); w = 100 -> 159.15 -> 160
    assert [job.periods(w) for w in job.frequencies] == [2, 10, 160]
    # ceil(2 w / 2 pi): 0.318 -> 1, exactly 2, 31.8 -> 32
    assert [job.discarded_periods(w) for w in job.frequencies] == [1, 2, 32]
    for w in job.frequencies:
        n = job.steps_per_period(w)
        assert job.n_steps(w) == job.periods(w) * n >= 10.0 / job.time_step(w) - 1e-9
        assert job.discard_steps(w) == job.discarded_periods(w) * n
    assert job.integration.periods is None and job.integration.discard_periods is None
    assert parse_job(canonical_text(job)) == job
    assert "duration = 10.0" in canonical_text(job) and "periods" not in canonical_text(job)


def test_a_duration_of_whole_periods_gives_the_same_tasks_as_periods():
    period = 2 * math.pi / 3.0
    by_time = parse_job("[shear]\nomega = [3.0]\n[integration]\n"
                        f"duration = {7 * period!r}\ndiscard_duration = {2 * period!r}\n")
    by_periods = parse_job("[shear]\nomega = [3.0]\n[integration]\nperiods = 7\n"
                           "discard_periods = 2\n")
    assert enumerate_tasks(by_time) == enumerate_tasks(by_periods)


@pytest.mark.parametrize("text, expected", [
    ("duration = 10.0\ndiscard_duration = 1.0\nperiods = 20\n",
     ["integration.periods = 20: does not apply", "integration.duration is not given",
      "remove integration.duration"]),
    ("duration = 10.0\ndiscard_duration = 1.0\ndiscard_periods = 2\n",
     ["integration.discard_periods = 2: does not apply", "integration.duration is not given"]),
    ("duration = 10.0\n", ["integration.discard_duration: is required when "
                           "integration.duration is given", "e.g. discard_duration = "]),
    ("discard_duration = 1.0\n", ["integration.discard_duration = 1.0: does not apply",
                                  "give integration.duration"]),
    ("duration = 10.0\ndiscard_duration = 10.0\n",
     ["integration.discard_duration = 10.0", "smaller than integration.duration",
      "0 <= discard_duration < 10"]),
    ("duration = 0.0\ndiscard_duration = 0.0\n", ["integration.duration = 0.0", "duration > 0"]),
    ("duration = 1.0\ndiscard_duration = 0.5\n",
     ["integration.discard_duration = 0.5", "leaves no whole period at omega = 1",
      "1 period(s)"]),
])
def test_bad_durations_name_the_key_and_what_is_allowed(text, expected):
    found = problems("[shear]\nomega = [1.0]\n[integration]\n" + text)
    assert len(found) == 1, found
    for part in expected:
        assert part in found[0], (part, found[0])


def test_duration_applies_only_to_oscillatory_shear():
    found = problems('[shear]\nprotocol = "steady"\n[integration]\nduration = 5.0\n')
    assert len(found) == 1 and "does not apply" in found[0] and "oscillatory" in found[0]


def test_an_override_switches_between_periods_and_duration():
    in_time = "[integration]\nduration = 10.0\ndiscard_duration = 2.0\n"
    job = parse_job(in_time, ["integration.periods=3", "integration.discard_periods=1"])
    assert (job.integration.periods, job.integration.discard_periods) == (3, 1)
    assert job.integration.duration is None and job.integration.discard_duration is None
    in_periods = "[integration]\nperiods = 10\ndiscard_periods = 2\n"
    job = parse_job(in_periods, ["integration.duration=3.0", "integration.discard_duration=1.0"])
    assert job.integration.periods is None and job.integration.duration == 3.0
    assert job.discarded_periods(2 * math.pi) == 1
    # switching to duration without its discard: the missing key is named
    found = problems(in_periods, ["integration.duration=3.0"])
    assert len(found) == 1 and "integration.discard_duration: is required" in found[0]
