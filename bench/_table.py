"""Tables of benchmark results: one definition, rendered as aligned text (terminal) or markdown (docs).

A :class:`Table` is plain data (title, column names, rows of already formatted strings, notes), so the
same object is printed by a benchmark, stored in its JSON file and turned into markdown by
``run_all.py --markdown``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any


def fmt_time_ns(ns: float) -> str:
    """A duration in the unit that keeps three significant digits readable (ns, us, ms)."""
    if ns != ns:  # NaN: the variant did not run
        return "n/a"
    if ns < 1e3:
        return f"{ns:.0f} ns"
    if ns < 1e6:
        return f"{ns / 1e3:.3g} us" if ns < 1e5 else f"{ns / 1e3:.0f} us"
    return f"{ns / 1e6:.3g} ms" if ns < 1e8 else f"{ns / 1e6:.0f} ms"


def fmt_ratio(ratio: float) -> str:
    """``12.3x``; ratios around 1 keep two decimals so that noise is visible as noise."""
    if ratio != ratio:
        return "n/a"
    if ratio >= 100:
        return f"{ratio:,.0f}x"
    if ratio >= 10:
        return f"{ratio:.1f}x"
    return f"{ratio:.2f}x"


def verdict(ok: bool | None) -> str:
    """The goal column: PASS, MISS, or '-' for rows that carry no goal (anchors, floors)."""
    return "-" if ok is None else ("PASS" if ok else "MISS")


@dataclass
class Table:
    """Rows of formatted cells under named columns, with a title and free-text notes below."""

    title: str
    columns: list[str]
    rows: list[list[str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def add(self, *cells: Any) -> None:
        if len(cells) != len(self.columns):
            raise ValueError(f"table {self.title!r} has {len(self.columns)} columns, got a row of {len(cells)}")
        self.rows.append([str(cell) for cell in cells])

    def _widths(self) -> list[int]:
        return [max(len(row[i]) for row in [self.columns, *self.rows]) for i in range(len(self.columns))]

    @staticmethod
    def _numeric(cell: str) -> bool:
        return bool(cell) and (cell[0].isdigit() or cell[0] in "-+<>~") and cell != "-"

    def text(self) -> str:
        """Aligned columns for a terminal; numbers right-aligned, words left-aligned."""
        widths = self._widths()

        def line(cells: list[str]) -> str:
            return "  ".join(c.rjust(w) if self._numeric(c) else c.ljust(w) for c, w in zip(cells, widths)).rstrip()

        rule = "  ".join("-" * w for w in widths)
        out = [self.title, "=" * len(self.title), line(self.columns), rule]
        out += [line(row) for row in self.rows]
        out += [f"  {note}" for note in self.notes]
        return "\n".join(out)

    def markdown(self) -> str:
        """A GitHub markdown table (notes become a list under it)."""
        aligns = ["---:" if any(self._numeric(row[i]) for row in self.rows) else "---"
                  for i in range(len(self.columns))]
        out = [f"**{self.title}**", "", "| " + " | ".join(self.columns) + " |", "| " + " | ".join(aligns) + " |"]
        out += ["| " + " | ".join(cell.replace("|", "\\|") for cell in row) + " |" for row in self.rows]
        if self.notes:
            out.append("")
            out += [f"- {note}" for note in self.notes]
        return "\n".join(out)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Table:
        return cls(**data)
