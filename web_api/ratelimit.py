"""A limit on failed authentication per client address: guessing keys gets 429.

Each presented key the API does not know counts as one failure of the caller's address. Once
an address has `limit` failures within `window_s`, every request from it that presents a
key is answered 429 with `Retry-After` (whole seconds until its oldest failure leaves the
window), without the key being looked at, so a guesser learns nothing while blocked.
Requests with a valid key are not counted and are not slowed while the address is under
the limit; requests without a key are not counted (they get their 401 at once).

Behind a reverse proxy every caller has the proxy's address: the limit then applies to the
proxy as a whole, which is the safe side.
"""

from __future__ import annotations

import math
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable


class AuthFailureLimiter:
    """Sliding-window count of failures per address; thread-safe (sync routes run in a
    thread pool)."""

    def __init__(
        self,
        limit: int = 10,
        window_s: float = 10.0,
        *,
        max_addresses: int = 10_000,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if limit < 1 or window_s <= 0:
            raise ValueError("limit must be >= 1 and window_s > 0")
        self.limit, self.window_s = limit, window_s
        self.max_addresses = max_addresses
        self.clock = clock
        self._failures: OrderedDict[str, deque[float]] = OrderedDict()
        self._lock = threading.Lock()

    def retry_after(self, address: str) -> int | None:
        """Seconds until `address` may try again, or None when it is not blocked."""
        with self._lock:
            times = self._current(address, self.clock())
            if times is None or len(times) < self.limit:
                return None
            # blocked until enough failures have aged out to go below the limit
            until = times[len(times) - self.limit] + self.window_s
            return max(1, math.ceil(until - self.clock()))

    def failed(self, address: str) -> None:
        """Count one failed authentication of `address`."""
        with self._lock:
            now = self.clock()
            times = self._current(address, now)
            if times is None:
                times = self._failures[address] = deque()
                while len(self._failures) > self.max_addresses:
                    self._failures.popitem(last=False)  # the least recently failing
            else:
                self._failures.move_to_end(address)
            times.append(now)
            while len(times) > self.limit:
                times.popleft()  # only the newest `limit` decide when the block ends

    def _current(self, address: str, now: float) -> deque[float] | None:
        times = self._failures.get(address)
        if times is None:
            return None
        while times and times[0] <= now - self.window_s:
            times.popleft()
        if not times:
            del self._failures[address]
            return None
        return times
