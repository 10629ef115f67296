"""Per-hop delay and loss measured in ns-3, as the live medium draws them (pure, seeded).

`gcs eval calibrate` flies static lines of UAVs in ns-3 (802.11b ad hoc, AODV) and writes, per
offered load and per hop count, the packets sent, the share lost and the delay quantiles of
the delivered ones (docs/calibration.md). A `CalibrationTable` is that file, validated; the
medium's `radio.model: calibrated` (`medium.radio.Channel`) draws each packet's fate from the
`LoadLevel` nearest its offered load:

* **load level**: the measured level whose offered load (bit/s of data, every sender of the
  line together) is nearest the medium's on a logarithmic scale (a tie goes to the higher
  load); below the lowest or above the highest level, that level. No interpolation between
  levels: each draw is one ns-3 actually measured.
* **loss**: lost with the hop count's measured loss ratio.
* **delay**: inverse-CDF sampling: a uniform draw u in [0, 1) is placed between the two stored
  quantiles around it and the delay interpolated between them on a logarithmic scale of delay
  (delays are positive and heavy-tailed: a few AODV route repairs take hundreds of ms while
  most packets take a millisecond); the lowest stored quantile is the smallest delay ever
  drawn, the highest (p100, the measured maximum) the largest.
* **beyond the largest measured hop count H**: each further hop adds, to every quantile, the
  mean per-hop growth of that quantile over the measured hops ((q_H - q_1) / (H - 1); for
  H = 1, q_1 itself), never negative and non-decreasing across the quantiles; the survival
  (1 - loss) is multiplied per further hop by the mean per-hop survival ratio
  ((s_H / s_1) ^ (1 / (H - 1)); for H = 1, s_1). Both are monotone in the hop count: more hops
  never means a shorter delay or fewer losses.

Each packet takes two uniform draws in [0, 1) from the caller's stream: the loss, then the
delay (taken even for a lost packet, so a packet's fate never shifts the next one's).
"""

from __future__ import annotations

import bisect
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fleetwire.files import CALIBRATION_BYTES, FileRefused, read_text_bounded

#: The table `gcs eval calibrate` ships (its default output).
DEFAULT_CALIBRATION = Path(__file__).resolve().parent / "calibration_ns3.json"
#: The `format` key of a calibration table, and the versions this module reads.
FORMAT = "fleetline-radio-calibration"
VERSIONS = (1,)


@dataclass(frozen=True, eq=False, repr=False)
class LoadLevel:
    """One offered load of the table: per hop count h (row h - 1, h = 1..H) the packets
    `sent`, the `loss_ratio` and the delay `quantiles_s` (H, P) at the table's probabilities
    `probabilities` (P,), 0 first and 1 last (a row of NaN: nothing was delivered)."""

    offered_load_bps: float
    rate_bps_per_node: float
    senders: int
    probabilities: np.ndarray
    sent: np.ndarray
    loss_ratio: np.ndarray
    quantiles_s: np.ndarray
    # derived in __post_init__: per-hop growth and survival beyond H, Python copies for the
    # one-packet path (a few float operations instead of numpy calls)
    increment_s: np.ndarray = field(init=False)
    survival_step: float = field(init=False)
    _probabilities: tuple[float, ...] = field(init=False)
    _log_rows: tuple[tuple[float, ...] | None, ...] = field(init=False)
    _survival: tuple[float, ...] = field(init=False)
    _last: tuple[float, ...] | None = field(init=False)
    _increment: tuple[float, ...] = field(init=False)

    def __post_init__(self) -> None:
        quantiles = np.asarray(self.quantiles_s, dtype=float)
        survival = 1.0 - np.asarray(self.loss_ratio, dtype=float)
        measured = len(quantiles)
        first, last = quantiles[0], quantiles[-1]
        if measured >= 2:
            growth = (last - first) / (measured - 1)
            step = survival[-1] / survival[0] if survival[0] > 0 else 0.0
            step = step ** (1.0 / (measured - 1))
        else:
            growth, step = first.copy(), float(survival[0])
        increment = np.maximum.accumulate(np.maximum(np.nan_to_num(growth, nan=0.0), 0.0))
        set_ = object.__setattr__
        set_(self, "increment_s", increment)
        set_(self, "survival_step", float(min(max(step, 0.0), 1.0)))
        set_(self, "_probabilities", tuple(float(p) for p in self.probabilities))
        set_(
            self,
            "_log_rows",
            tuple(
                None if np.isnan(row).any() else tuple(math.log(v) for v in row.tolist())
                for row in quantiles
            ),
        )
        set_(self, "_survival", tuple(survival.tolist()))
        set_(self, "_last", None if np.isnan(last).any() else tuple(last.tolist()))
        set_(self, "_increment", tuple(increment.tolist()))

    def __repr__(self) -> str:
        return (
            f"LoadLevel(offered_load_bps={self.offered_load_bps:g}, "
            f"hops=1..{self.max_hops}, quantiles={len(self.probabilities)})"
        )

    @property
    def max_hops(self) -> int:
        """H, the largest measured hop count."""
        return len(self.quantiles_s)

    # ------------------------------------------------------------------ per hop count
    def survival(self, hops: np.ndarray) -> np.ndarray:
        """(M,) probability that a packet over `hops` (M,) hops (>= 1) is delivered."""
        hops = np.asarray(hops, dtype=int)
        measured = 1.0 - np.asarray(self.loss_ratio, dtype=float)
        rows = np.minimum(hops, self.max_hops) - 1
        beyond = np.maximum(hops - self.max_hops, 0)
        return measured[rows] * self.survival_step**beyond

    def quantiles(self, hops: np.ndarray) -> np.ndarray:
        """(M, P) delay quantiles (s) of packets over `hops` (M,) hops (>= 1), extrapolated
        beyond H (module docstring); NaN rows: nothing delivered at that hop count."""
        hops = np.asarray(hops, dtype=int)
        rows = np.minimum(hops, self.max_hops) - 1
        beyond = np.maximum(hops - self.max_hops, 0).astype(float)
        return self.quantiles_s[rows] + beyond[:, None] * self.increment_s[None, :]

    # ------------------------------------------------------------------ draws
    def delays(
        self, hops: np.ndarray, loss_draws: np.ndarray, delay_draws: np.ndarray
    ) -> np.ndarray:
        """(M,) delays (s) of packets over `hops` (M,) hops (>= 1), NaN where lost, from two
        uniform draws in [0, 1) per packet (vectorised; the same numbers as `delay`)."""
        hops = np.asarray(hops, dtype=int).reshape(-1)
        if not len(hops):
            return np.zeros(0)
        if (hops < 1).any():
            raise ValueError("hops must be >= 1")
        loss_draws = np.asarray(loss_draws, dtype=float).reshape(-1)
        delay_draws = np.asarray(delay_draws, dtype=float).reshape(-1)
        probabilities = np.asarray(self.probabilities, dtype=float)
        table = self.quantiles(hops)
        low = np.clip(np.searchsorted(probabilities, delay_draws, side="right") - 1, 0,
                      len(probabilities) - 2)  # fmt: skip
        picked = np.arange(len(hops))
        with np.errstate(divide="ignore", invalid="ignore"):
            below, above = np.log(table[picked, low]), np.log(table[picked, low + 1])
        fraction = (delay_draws - probabilities[low]) / (
            probabilities[low + 1] - probabilities[low]
        )
        out = np.exp(below + fraction * (above - below))
        out[loss_draws >= self.survival(hops)] = np.nan
        return out

    def delay(self, hops: int, loss_draw: float, delay_draw: float) -> float | None:
        """Delay (s) of one packet over `hops` (>= 1) hops, or None if lost, from two uniform
        draws in [0, 1) (the one-packet path of `delays`, in plain Python)."""
        if hops < 1:
            raise ValueError("hops must be >= 1")
        measured = self.max_hops
        probabilities = self._probabilities
        low = min(
            max(bisect.bisect_right(probabilities, delay_draw) - 1, 0), len(probabilities) - 2
        )
        if hops <= measured:
            if loss_draw >= self._survival[hops - 1]:
                return None
            row = self._log_rows[hops - 1]
            if row is None:
                return None
            below, above = row[low], row[low + 1]
        else:
            extra = hops - measured
            if loss_draw >= self._survival[-1] * self.survival_step**extra:
                return None
            last = self._last
            if last is None:
                return None
            below = math.log(last[low] + extra * self._increment[low])
            above = math.log(last[low + 1] + extra * self._increment[low + 1])
        fraction = (delay_draw - probabilities[low]) / (probabilities[low + 1] - probabilities[low])
        return math.exp(below + fraction * (above - below))


@dataclass(frozen=True, eq=False, repr=False)
class CalibrationTable:
    """A calibration file (`gcs eval calibrate`): its load levels, lowest load first, and what
    made it (`made_by`, `ns3`, `scenario`: kept as read, for the record)."""

    source: str
    probabilities: tuple[float, ...]
    levels: tuple[LoadLevel, ...]
    made_by: dict[str, Any] = field(default_factory=dict)
    ns3: dict[str, Any] = field(default_factory=dict)
    scenario: dict[str, Any] = field(default_factory=dict)

    def __repr__(self) -> str:
        loads = ", ".join(f"{level.offered_load_bps:g}" for level in self.levels)
        return f"CalibrationTable({self.source!r}, offered loads [{loads}] bit/s)"

    @property
    def offered_loads_bps(self) -> np.ndarray:
        return np.array([level.offered_load_bps for level in self.levels])

    def level(self, offered_load_bps: float | None) -> LoadLevel:
        """The level nearest `offered_load_bps` on a log scale (a tie: the higher load); None,
        0 or below the lowest level: the lowest."""
        loads = self.offered_loads_bps
        if offered_load_bps is None or not offered_load_bps > 0:
            return self.levels[0]
        distance = np.abs(np.log(loads) - math.log(offered_load_bps))
        best = np.flatnonzero(distance <= distance.min() * (1 + 1e-12) + 1e-15)
        return self.levels[int(best[-1])]

    def sample(
        self, hops: np.ndarray, offered_load_bps: float | None, rng: np.random.Generator
    ) -> np.ndarray:
        """(M,) delays (s), NaN where lost, of packets over `hops` (M,) at that load, drawn
        from `rng` (two uniform draws per packet: loss, delay)."""
        hops = np.asarray(hops, dtype=int).reshape(-1)
        draws = rng.random((len(hops), 2))
        return self.level(offered_load_bps).delays(hops, draws[:, 0], draws[:, 1])


# --------------------------------------------------------------------------- loading
def load_calibration(path: str | Path = DEFAULT_CALIBRATION) -> CalibrationTable:
    """The calibration table in `path` (JSON written by `gcs eval calibrate`); a missing or
    bad file raises ValueError naming the file and the key."""
    path = Path(path)
    try:
        text = read_text_bounded(path, CALIBRATION_BYTES)
    except FileRefused as error:
        raise ValueError(f"{path}: expected a calibration file: {error}") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path}: expected a UTF-8 JSON calibration file") from None
    except OSError as error:
        raise ValueError(
            f"{path}: expected a readable calibration file ({error.strerror})"
        ) from None
    try:
        data = json.loads(text)
    except ValueError as error:
        raise ValueError(f"{path}: expected JSON ({error})") from None
    return calibration_from_json(data, str(path))


def calibration_from_json(data: Any, source: str = "<calibration>") -> CalibrationTable:
    """The table of an already-parsed calibration object (validated: ValueError naming
    `source` and the key)."""
    check = _Checker(source)
    top = check.mapping(data, "", ("format", "version", "quantiles", "levels"))
    if top["format"] != FORMAT:
        raise check.fail("format", f"{FORMAT!r}, got {top['format']!r}")
    if top["version"] not in VERSIONS:
        raise check.fail("version", f"one of {VERSIONS}, got {top['version']!r}")
    probabilities = check.numbers(top["quantiles"], "quantiles", low=0.0, high=1.0)
    if (
        len(probabilities) < 2
        or probabilities[0] != 0.0
        or probabilities[-1] != 1.0
        or not (np.diff(probabilities) > 0).all()
    ):
        raise check.fail("quantiles", "increasing probabilities from 0 to 1 (at least two)")
    levels_data = top["levels"]
    if not isinstance(levels_data, list) or not levels_data:
        raise check.fail("levels", "a non-empty list of load levels")
    levels = [
        _level(check, item, f"levels[{k}]", probabilities) for k, item in enumerate(levels_data)
    ]
    loads = [level.offered_load_bps for level in levels]
    if sorted(set(loads)) != loads:
        raise check.fail("levels", "offered_load_bps increasing from one level to the next")
    return CalibrationTable(
        source=source,
        probabilities=tuple(probabilities.tolist()),
        levels=tuple(levels),
        made_by=dict(top.get("made_by") or {}),
        ns3=dict(top.get("ns3") or {}),
        scenario=dict(top.get("scenario") or {}),
    )


def _level(check: _Checker, item: Any, path: str, probabilities: np.ndarray) -> LoadLevel:
    level = check.mapping(item, path, ("offered_load_bps", "hops"))
    load = check.number(level["offered_load_bps"], f"{path}.offered_load_bps", positive=True)
    rows = level["hops"]
    if not isinstance(rows, list) or not rows:
        raise check.fail(f"{path}.hops", "a non-empty list, one row per hop count from 1")
    sent, loss, quantiles = [], [], []
    for index, row_data in enumerate(rows):
        where = f"{path}.hops[{index}]"
        row = check.mapping(row_data, where, ("hops", "sent", "loss_ratio", "delay_s"))
        if row["hops"] != index + 1 or isinstance(row["hops"], bool):
            raise check.fail(f"{where}.hops", f"{index + 1} (hop counts 1, 2, ... in order)")
        count = row["sent"]
        if not isinstance(count, int) or isinstance(count, bool) or count < 1:
            raise check.fail(f"{where}.sent", f"an integer >= 1, got {count!r}")
        ratio = check.number(row["loss_ratio"], f"{where}.loss_ratio", low=0.0, high=1.0)
        delays = row["delay_s"]
        if delays is None:  # nothing delivered
            if ratio != 1.0:
                raise check.fail(f"{where}.delay_s", "delay quantiles (loss_ratio is below 1)")
            values = np.full(len(probabilities), np.nan)
        else:
            values = check.numbers(delays, f"{where}.delay_s", positive=True)
            if len(values) != len(probabilities):
                raise check.fail(
                    f"{where}.delay_s",
                    f"{len(probabilities)} delays (s), one per quantile, got {len(values)}",
                )
            if (np.diff(values) < 0).any():
                raise check.fail(f"{where}.delay_s", "delays (s) non-decreasing with the quantile")
        sent.append(count)
        loss.append(ratio)
        quantiles.append(values)
    rate = level.get("rate_bps_per_node")
    senders = level.get("senders")
    return LoadLevel(
        offered_load_bps=load,
        rate_bps_per_node=float(rate) if isinstance(rate, int | float) else math.nan,
        senders=int(senders) if isinstance(senders, int) else 0,
        probabilities=probabilities,
        sent=np.array(sent, dtype=int),
        loss_ratio=np.array(loss, dtype=float),
        quantiles_s=np.array(quantiles, dtype=float).reshape(len(rows), len(probabilities)),
    )


class _Checker:
    """Validation helpers: each failure is a ValueError `SOURCE: KEY: expected ...`."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, path: str, expected: str) -> ValueError:
        where = f"{self.source}: {path}" if path else self.source
        return ValueError(f"{where}: expected {expected}")

    def mapping(self, value: Any, path: str, required: tuple[str, ...]) -> dict:
        if not isinstance(value, dict):
            raise self.fail(path, f"an object with {', '.join(required)}")
        for key in required:
            if key not in value:
                raise self.fail(f"{path}.{key}" if path else key, "this key (missing)")
        return value

    def number(
        self,
        value: Any,
        path: str,
        *,
        low: float | None = None,
        high: float | None = None,
        positive: bool = False,
    ) -> float:
        if (
            not isinstance(value, int | float)
            or isinstance(value, bool)
            or not math.isfinite(value)
            or (positive and value <= 0)
            or (low is not None and value < low)
            or (high is not None and value > high)
        ):
            bounds = ["> 0"] if positive else []
            bounds += [f">= {low:g}"] if low is not None else []
            bounds += [f"<= {high:g}"] if high is not None else []
            wanted = " ".join(["a finite number", " and ".join(bounds)]).strip()
            raise self.fail(path, f"{wanted}, got {value!r}")
        return float(value)

    def numbers(self, value: Any, path: str, **bounds: Any) -> np.ndarray:
        if not isinstance(value, list):
            raise self.fail(path, f"a list of numbers, got {value!r}")
        return np.array(
            [self.number(v, f"{path}[{k}]", **bounds) for k, v in enumerate(value)], dtype=float
        )
