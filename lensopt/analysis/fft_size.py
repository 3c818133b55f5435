"""FFT lengths: the smallest 5-smooth length (2^a 3^b 5^c) at or above n, as ``scipy.fft.next_fast_len(n,
real=True)`` returns, without importing scipy.fft (0.3 s at start-up, for one integer function)."""

from __future__ import annotations

__all__ = ["next_fast_len"]


def next_fast_len(n: int) -> int:
    """Smallest 2^a 3^b 5^c ≥ n (n ≥ 1): a fast size for torch's (pocketfft) real FFTs."""
    if n <= 6:
        return max(int(n), 1)
    best = 1 << (int(n) - 1).bit_length()  # the next power of two is 5-smooth
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            m = p35  # the smallest m = p35 · 2^a ≥ n
            if m < n:
                m <<= (-(-n // m) - 1).bit_length()
            best = min(best, m)
            p35 *= 3
        p5 *= 5
    return best
