"""A small self-contained HTML page of tables (the report's inline tables)."""

from __future__ import annotations

import html
from pathlib import Path
from typing import Sequence

import pandas as pd

__all__ = ["html_page", "write_html"]

_STYLE = """
body { font-family: sans-serif; font-size: 13px; margin: 8px; }
table { border-collapse: collapse; margin-bottom: 14px; }
th, td { border: 1px solid #ccc; padding: 3px 7px; text-align: right; }
th { background: #eef2f7; }
td:first-child, th:first-child { text-align: left; }
h4 { margin: 10px 0 4px; }
p.note { color: #444; max-width: 60em; }
"""


def html_page(title: str, tables: Sequence[tuple[str, pd.DataFrame]], notes: Sequence[str] = ()) -> str:
    """A standalone HTML page: title, notes, then each (caption, table)."""
    parts = [
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>",
        f"<style>{_STYLE}</style></head><body><h3>{html.escape(title)}</h3>",
    ]
    parts += [f"<p class='note'>{html.escape(n)}</p>" for n in notes]
    for cap, df in tables:
        if cap:
            parts.append(f"<h4>{html.escape(cap)}</h4>")
        parts.append(df.to_html(border=0, na_rep="", float_format=lambda v: f"{v:.4g}", escape=True))
    parts.append("</body></html>")
    return "\n".join(parts)


def write_html(
    path: str | Path, title: str, tables: Sequence[tuple[str, pd.DataFrame]], notes: Sequence[str] = ()
) -> Path:
    """Write `html_page` to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(html_page(title, tables, notes), encoding="utf-8")
    return path
