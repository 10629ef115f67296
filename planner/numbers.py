"""Numbers in messages: never rounded onto the limit they break, counts with their plural.

A refusal that compares a measured value with a limit must not print them equal ("at least
5 m ... is 5 m from it" for 4.999 m): `fmt_against` prints the value with the fewest
significant digits, from `digits` up, at which it and the limit read differently, and the
limit is printed the same way (`fmt_against(limit, value)`: the precision depends only on the
pair). Pure (no numpy), used by the planner's and the mission file's messages.
"""

from __future__ import annotations

import math

#: Significant digits that tell any two different floats apart (IEEE 754 double).
MAX_DIGITS = 17


def digits_against(value: float, limit: float, digits: int = 3) -> int:
    """The fewest significant digits >= `digits` at which `value` and `limit` print
    differently (`digits` when they are equal or not both finite)."""
    value, limit = float(value), float(limit)
    if value == limit or not (math.isfinite(value) and math.isfinite(limit)):
        return digits
    for p in range(digits, MAX_DIGITS):
        if f"{value:.{p}g}" != f"{limit:.{p}g}":
            return p
    return MAX_DIGITS


def fmt_against(value: float, limit: float, digits: int = 3) -> str:
    """`value` with `digits` significant digits, or more until it no longer reads as `limit`:
    fmt_against(4.999, 5) == "4.999", fmt_against(9.9999999, 10) == "9.9999999". Print the
    limit as fmt_against(limit, value, digits): both then have the same precision."""
    return f"{float(value):.{digits_against(value, limit, digits)}g}"


def plural(count: int, noun: str, nouns: str | None = None) -> str:
    """`count` and `noun`, in the plural unless the count is one: "1 UAV", "2 UAVs"."""
    return f"{count} {noun if count == 1 else nouns or noun + 's'}"
