"""Suite-wide settings that keep the tests meaningful on a loaded machine.

Hypothesis's per-example deadline (200 ms) measures the machine's load, not our code: at
load 20 a 50 ms example takes 300 ms and fails with no defect behind it. Speed is measured in
bench/, so the suite runs every property without a deadline and without the "too slow"
health checks; tests that set their own `@settings` inherit these defaults.
"""

from __future__ import annotations

from hypothesis import HealthCheck, settings

settings.register_profile(
    "fmscell",
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.load_profile("fmscell")
