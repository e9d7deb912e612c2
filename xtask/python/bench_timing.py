"""Wall-clock timing shared by the benchmark scripts (bench_operators.py, bench_noise.py)."""

import time


def time_ms(runs, fn):
    """(median, min) wall time in milliseconds of `runs` calls after a warm-up."""
    fn()
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    times.sort()
    return times[len(times) // 2], times[0]
