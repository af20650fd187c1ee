"""Messages of a signal atom's topic: a time span -> (time ns, value) pairs as a driver publishes them."""

from __future__ import annotations

import math

from tubempc.strategies._common import st

__all__ = ["SIGNAL_LEVELS", "signal_messages"]

#: values around the thresholds of the example scenario's speed atoms (0.3 and 0.5 m/s), and a NaN
SIGNAL_LEVELS = (0.1, 0.3, 0.4, 0.5, 0.6, math.nan)


@st.composite
def signal_messages(draw: st.DrawFn, start_ns: int, end_ns: int, *, period_ns: int = 100_000_000,
                    levels: tuple[float, ...] = SIGNAL_LEVELS, lead_ns: int = 300_000_000,
                    jitter_ns: tuple[int, ...] = (0, 0, 0, 1, -1, 7_000_000, 60_000_000)
                    ) -> tuple[tuple[int, float], ...]:
    """Messages every ``period_ns`` (plus a drawn ``jitter_ns``) from up to ``lead_ns`` before ``start_ns`` to past
    ``end_ns``, values from ``levels``; about one in ten dropped (a silence) and one in fifteen sent twice, with the
    same value or another (a conflict). At least one message."""
    t = start_ns - draw(st.integers(0, lead_ns))
    out: list[tuple[int, float]] = []
    while t <= end_ns + 2 * period_ns:
        if draw(st.integers(0, 9)):
            value = draw(st.sampled_from(levels))
            out.append((t, value))
            if not draw(st.integers(0, 14)):
                out.append((t, value if draw(st.booleans()) else draw(st.sampled_from(levels))))
        t += period_ns + draw(st.sampled_from(jitter_ns))
    return tuple(out) or ((start_ns, draw(st.sampled_from(levels))),)
