"""breastplan.clock: the one clock of the commands, the ingest pipeline and the benchmarks."""
from breastplan.clock import Clock


def test_steps_accumulate_milliseconds_and_seconds_count_from_construction():
    clock = Clock()
    with clock("a"):
        sum(range(1000))
    first = clock.ms["a"]
    with clock("a"):
        sum(range(1000))
    with clock("b"):
        pass
    assert list(clock.ms) == ["a", "b"]
    assert clock.ms["a"] > first > 0 and clock.ms["b"] >= 0
    assert clock.seconds >= round((clock.ms["a"] + clock.ms["b"]) / 1e3, 3) - 0.001
    assert clock.seconds == round(clock.seconds, 3)
