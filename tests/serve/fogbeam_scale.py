"""FOGBEAM_TEST_SCALE for the Python end-to-end tests: the same knob as tests/test_scale.hpp
(docs/reliability.md). A number in (0, 1], 1 (the full size, what the plain build runs) when unset
or empty; scripts/asan.sh sets 0.25. Tests that take a frame count from a constant render fewer
frames with it, never fewer than their checks need."""
import math
import os


def scale():
    """FOGBEAM_TEST_SCALE as a float; ValueError (the test fails with the reason) unless in (0, 1]."""
    text = os.environ.get("FOGBEAM_TEST_SCALE", "")
    if text == "":
        return 1.0
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0.0 < value <= 1.0:  # also refuses nan
        raise ValueError(f'FOGBEAM_TEST_SCALE="{text}": expected a number in (0, 1]')
    return value


def scaled(n, minimum=1):
    """n scaled, rounded up, never below minimum nor above n (n itself at full size)."""
    return min(n, max(minimum, math.ceil(n * scale() - 1e-9)))
