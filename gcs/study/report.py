"""`gcs eval study-report DIR`: per axis of the study, each kept metric's mean and 95 %
confidence interval (Student's t) over the runs at each value of the axis (all other axes
pooled), as Markdown tables, `report.json` and one figure per swept axis; and each metric
against the obstacle density of the maps when the maps vary.

Besides the kept metrics, every table has `plan_s` (the planner's wall time) and the map's
`density` and `obstacles`. A failed run counts in `failed` and in none of the means; a boolean
metric's mean is the fraction of runs where it held.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

DPI = 110
#: Two-sided 95 % quantiles of Student's t for 1..30 degrees of freedom.
_T95 = (
    12.706204736, 4.302652730, 3.182446305, 2.776445105, 2.570581836, 2.446911851,
    2.364624252, 2.306004135, 2.262157163, 2.228138852, 2.200985160, 2.178812830,
    2.160368656, 2.144786688, 2.131449546, 2.119905299, 2.109815578, 2.100922040,
    2.093024054, 2.085963447, 2.079613845, 2.073873068, 2.068657610, 2.063898562,
    2.059538553, 2.055529439, 2.051830516, 2.048407142, 2.045229642, 2.042272456,
)  # fmt: skip
_Z975 = 1.959963984540054
#: Extra columns of every table besides the kept metrics: (name, where in a row).
EXTRA = (("plan_s", ("meta", "plan_s")), ("density", ("map", "density")),
         ("obstacles", ("map", "obstacles")))  # fmt: skip


def t95(df: int) -> float:
    """Two-sided 95 % quantile of Student's t with `df` degrees of freedom (a table to 30,
    then the Cornish-Fisher expansion, within 1e-6)."""
    if df < 1:
        return math.nan
    if df <= len(_T95):
        return _T95[df - 1]
    z = _Z975
    return (
        z
        + (z**3 + z) / (4 * df)
        + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * df**2)
        + (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / (384 * df**3)
        + (79 * z**9 + 776 * z**7 + 1482 * z**5 - 1920 * z**3 - 945 * z) / (92160 * df**4)
    )


@dataclass(frozen=True)
class Estimate:
    """Mean of `n` finite values and its 95 % confidence interval (NaN bounds when n < 2)."""

    n: int
    mean: float
    low: float
    high: float


def mean_ci(values: np.ndarray) -> Estimate:
    """Mean and 95 % t interval of the finite entries of `values`."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if not v.size:
        return Estimate(0, math.nan, math.nan, math.nan)
    mean = float(v.mean())
    if v.size < 2:
        return Estimate(1, mean, math.nan, math.nan)
    spread = 0.0 if np.ptp(v) == 0 else float(v.std(ddof=1))  # equal values: exactly 0
    half = t95(v.size - 1) * spread / math.sqrt(v.size)
    return Estimate(int(v.size), mean, mean - half, mean + half)


def _number(value: Any) -> float:
    if isinstance(value, bool):
        return float(value)
    if isinstance(value, int | float):
        return float(value)
    return math.nan


def _pick(row: dict, where: tuple[str, ...]) -> Any:
    value: Any = row
    for key in where:
        value = value.get(key) if isinstance(value, dict) else None
    return value


def _key(value: Any) -> str:
    return json.dumps(value, sort_keys=True)


def _sort_key(value: Any) -> tuple:
    if value is None:
        return (0, 0.0, "")
    if isinstance(value, int | float) and not isinstance(value, bool):
        return (1, float(value), "")
    return (2, 0.0, _key(value))


def value_text(value: Any) -> str:
    if value is None:
        return "none"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, dict):
        return ", ".join(f"{k}: {v}" for k, v in value.items())
    return str(value)


@dataclass(frozen=True)
class AxisTable:
    """One axis: its values (sorted), the runs and failures at each, and per column (kept
    metrics, then `EXTRA`) one `Estimate` per value."""

    axis: str
    values: tuple[Any, ...]
    runs: tuple[int, ...]
    failed: tuple[int, ...]
    columns: dict[str, tuple[Estimate, ...]]


def columns_of(rows: list[dict], metrics: list[str]) -> dict[str, np.ndarray]:
    """Each kept metric and `EXTRA` column as a float array over `rows` (NaN: missing or a
    failed run)."""
    ok = np.array([not row.get("error") for row in rows], bool)
    out = {}
    for name in metrics:
        out[name] = np.array([_number(_pick(r, ("metrics", name))) for r in rows], float)
    for name, where in EXTRA:
        out[name] = np.array([_number(_pick(r, where)) for r in rows], float)
    for name in out:
        out[name][~ok] = np.nan
    return out


def axis_table(rows: list[dict], axis: str, values: list, metrics: list[str]) -> AxisTable:
    """The table of `axis` over `rows`."""
    ordered = tuple(sorted(values, key=_sort_key))
    keys = np.array([_key(_pick(r, ("params", axis))) for r in rows])
    failed = np.array([bool(r.get("error")) for r in rows], bool)
    data = columns_of(rows, metrics)
    masks = [keys == _key(v) for v in ordered]
    return AxisTable(
        axis=axis,
        values=ordered,
        runs=tuple(int(m.sum()) for m in masks),
        failed=tuple(int((m & failed).sum()) for m in masks),
        columns={name: tuple(mean_ci(column[m]) for m in masks) for name, column in data.items()},
    )


def _cell(e: Estimate) -> str:
    if e.n == 0:
        return "n/a"
    if e.n == 1:
        return f"{e.mean:.4g} (n=1)"
    return f"{e.mean:.4g} ± {(e.high - e.low) / 2:.2g} (n={e.n})"


def table_markdown(table: AxisTable) -> str:
    heads = [value_text(v) for v in table.values]
    lines = [
        f"### {table.axis}",
        "",
        f"| metric | {' | '.join(heads)} |",
        "|---|" + "---|" * len(heads),
        f"| runs | {' | '.join(map(str, table.runs))} |",
        f"| failed | {' | '.join(map(str, table.failed))} |",
    ]
    for name, estimates in table.columns.items():
        lines.append(f"| {name} | {' | '.join(_cell(e) for e in estimates)} |")
    return "\n".join(lines) + "\n"


def _finite_or_none(x: float) -> float | None:
    return x if math.isfinite(x) else None


def table_json(table: AxisTable) -> dict[str, Any]:
    return {
        "values": list(table.values),
        "runs": list(table.runs),
        "failed": list(table.failed),
        "metrics": {
            name: {
                "n": [e.n for e in est],
                "mean": [_finite_or_none(e.mean) for e in est],
                "low": [_finite_or_none(e.low) for e in est],
                "high": [_finite_or_none(e.high) for e in est],
            }
            for name, est in table.columns.items()
        },
    }


def axis_figure(table: AxisTable, title: str) -> Figure | None:
    """Each column with a finite mean against the axis: mean and 95 % interval."""
    shown = [(n, e) for n, e in table.columns.items() if any(x.n for x in e)]
    if not shown:
        return None
    numeric = all(_sort_key(v)[0] == 1 for v in table.values)
    x = np.array([float(v) for v in table.values]) if numeric else np.arange(len(table.values))
    cols = min(4, len(shown))
    rows = math.ceil(len(shown) / cols)
    fig = Figure(figsize=(3.4 * cols, 2.6 * rows + 0.6), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax, (name, est) in zip(axes.ravel(), shown, strict=False):
        mean = np.array([e.mean for e in est])
        low = np.array([e.low for e in est])
        high = np.array([e.high for e in est])
        err = np.vstack([np.nan_to_num(mean - low), np.nan_to_num(high - mean)])
        ax.errorbar(x, mean, yerr=err, fmt="o-", capsize=3, lw=1.0, ms=4)
        ax.set_title(name, fontsize=9)
        ax.grid(alpha=0.3)
        if not numeric:
            ax.set_xticks(x, [value_text(v) for v in table.values], fontsize=7)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[len(shown) :]:
        ax.set_visible(False)
    fig.suptitle(f"{title}: mean and 95 % CI against {table.axis}")
    return fig


def density_figure(rows: list[dict], metrics: list[str], title: str) -> Figure | None:
    """Each metric of each succeeded run against its map's obstacle density (a scatter)."""
    data = columns_of(rows, metrics)
    density = data.pop("density")
    if np.unique(density[np.isfinite(density)]).size < 2:
        return None
    shown = [(n, v) for n, v in data.items() if np.isfinite(v).any()]
    cols = min(4, len(shown))
    count = math.ceil(len(shown) / cols)
    fig = Figure(figsize=(3.4 * cols, 2.6 * count + 0.6), layout="constrained")
    axes = fig.subplots(count, cols, squeeze=False)
    for ax, (name, values) in zip(axes.ravel(), shown, strict=False):
        ax.scatter(density, values, s=10, alpha=0.7)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("obstacle density", fontsize=8)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[len(shown) :]:
        ax.set_visible(False)
    fig.suptitle(f"{title}: each run against the obstacle density of its map")
    return fig


@dataclass(frozen=True)
class Report:
    """What `write_report` wrote."""

    tables: tuple[AxisTable, ...]
    files: tuple[Path, ...]
    runs: int
    failed: int
    ignored: int


def study_rows(summary: dict, rows: list[dict]) -> tuple[list[dict], int]:
    """The rows of the study `summary` (`study.json`), sorted by run index; and how many
    rows of the table belong to no run of it (another study in the same folder)."""
    ids = set(summary["runs"])
    mine = sorted((r for r in rows if r["id"] in ids), key=lambda r: r.get("index", 0))
    return mine, len(rows) - len(mine)


def write_report(summary: dict, rows: list[dict], out: Path) -> Report:
    """Tables (`report.md`, `report.json`) and figures (`axis_<name>.png`,
    `density.png`) of the study `summary` over its `rows`, in `out`."""
    rows, ignored = study_rows(summary, rows)
    metrics = list(summary["metrics"])
    name = summary["name"]
    tables = tuple(
        axis_table(rows, axis, values, metrics) for axis, values in summary["axes"].items()
    )
    out.mkdir(parents=True, exist_ok=True)
    failed = sum(1 for r in rows if r.get("error"))
    total = len(summary["runs"])
    lines = [
        f"# Study {name}",
        "",
        f"{len(rows)} of {total} runs in the table, {failed} failed. Each cell: mean ± half "
        "the 95 % confidence interval (Student's t) over the succeeded runs at that value, "
        "every other axis pooled (n: runs with a value).",
        "",
    ]
    lines += [table_markdown(t) for t in tables]
    errors: dict[str, int] = {}
    for r in rows:
        if r.get("error"):
            errors[r["error"]] = errors.get(r["error"], 0) + 1
    if errors:
        lines += ["### errors", "", "| runs | error |", "|---|---|"]
        lines += [f"| {n} | {e} |" for e, n in sorted(errors.items(), key=lambda x: -x[1])]
    files = [out / "report.md", out / "report.json"]
    files[0].write_text("\n".join(lines) + "\n")
    files[1].write_text(
        json.dumps(
            {
                "name": name,
                "runs": total,
                "rows": len(rows),
                "failed": failed,
                "axes": {t.axis: table_json(t) for t in tables},
            },
            indent=1,
            allow_nan=False,
        )
    )
    for table in tables:
        if len(table.values) < 2:
            continue
        figure = axis_figure(table, name)
        if figure is not None:
            path = out / f"axis_{table.axis}.png"
            figure.savefig(path, dpi=DPI)
            files.append(path)
    figure = density_figure(rows, metrics, name) if rows else None
    if figure is not None:
        figure.savefig(out / "density.png", dpi=DPI)
        files.append(out / "density.png")
    return Report(tables, tuple(files), len(rows), failed, ignored)
