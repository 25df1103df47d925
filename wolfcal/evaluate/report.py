"""The evaluation report: one list of blocks rendered as self-contained HTML (pictures embedded as base64 PNG) and as
Markdown (pictures as files beside it), plus the before/after table printed on the terminal.

Blocks: ("h1"|"h2"|"p"|"pre", text), ("banner", (good, text)), ("table", (headers, rows, marked_rows)),
("figure", (file name, caption)).
"""

from __future__ import annotations

import base64
import html
from typing import Any

# (kind, content): the content's type depends on the kind (module docstring), so it is checked where rendered
Block = tuple[str, Any]


def _num(value: float | None, scale: float = 1.0, digits: int = 2) -> str:
    return "n/a" if value is None else f"{value * scale:.{digits}f}"


def headline_rows(metrics: dict) -> list[list[str]]:
    """Rows (quantity, before, after) of the before/after comparison, in display units."""
    b, a = metrics["before"], metrics["after"]
    rows = [
        ["reprojection RMS per axis [px]", _num(b["rms_px"], digits=3), _num(a["rms_px"], digits=3)],
        ["largest corner error [px]", _num(b["max_px"]), _num(a["max_px"])],
        [
            "tag-grid mean distance (2019 study's metric) [mm]",
            _num(b["tag_grid_mean_mm"], digits=1),
            _num(a["tag_grid_mean_mm"], digits=1),
        ],
    ]
    for row in metrics["ground"]["rows"]:
        before, after = row["models"]["before"], row["models"]["after"]
        rows.append([f"ground error, ball at {row['distance_m']:g} m [cm]", ground_cell(before), ground_cell(after)])
    return rows


NO_TRUTH = "n/a (no truth)"


def ground_cell(entry: dict) -> str:
    """A ground error [cm] of `ground.ground_errors`' model entry: n/a without a truth to measure it against, 'above
    horizon' where the model puts the ball above it."""
    if entry.get("no_truth"):
        return NO_TRUTH
    return "above horizon" if entry["error_m"] is None else _num(entry["error_m"], 100, 1)


def column_headers(metrics: dict) -> list[str]:
    """The before/after table's headers: what 'before' is (the present calibration or the input URDF)."""
    return ["", f"before ({metrics.get('before_model', 'input URDF')})", "after (calibrated)"]


def measured_ground_rows(metrics: dict) -> list[list[str]]:
    """Rows (quantity, before, after) of the ground error measured on held-out floor views (none without)."""
    measured: dict = (metrics["ground"].get("measured") or {}).get("models") or {}
    return [[f"measured ground error (floor views), ball at {row['distance_m']:g} m [cm, 1 sigma]",
             *(_measured(measured[m]["rows"][k]) for m in ("before", "after"))]
            for k, row in enumerate(measured["before"]["rows"] if measured else [])]  # fmt: skip


def _measured(row: dict) -> str:
    """'error +- std' [cm] of a measured ground error row, 'n/a' where not measured (above the horizon)."""
    if row["error_m"] is None:
        return "n/a"
    return f"{_num(row['error_m'], 100, 1)} +- {_num(row['std_m'], 100, 1)}"


def before_after_table(metrics: dict) -> str:
    """Plain-text before/after table for a terminal (with the measured ground error, a section of the report)."""
    rows = [column_headers(metrics)] + headline_rows(metrics) + measured_ground_rows(metrics)
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    lines = [f"{r[0]:<{widths[0]}}  {r[1]:>{widths[1]}}  {r[2]:>{widths[2]}}" for r in rows]
    lines.insert(1, "-" * len(lines[0]))
    return "\n".join(lines)


def render_html(blocks: list[Block], figures: dict[str, bytes], title: str) -> str:
    """Self-contained HTML page: inline CSS, pictures as data URIs."""
    out = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{html.escape(title)}</title>",
        "<style>body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}"
        "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}"
        "td:first-child,th:first-child{text-align:left}tr.mark{background:#fde2e2}"
        ".good{background:#e3f4e1;border-left:6px solid #2e8b2e;padding:.8em}"
        ".bad{background:#fde2e2;border-left:6px solid #c0392b;padding:.8em}"
        "figure{margin:1.5em 0}img{max-width:100%;border:1px solid #ddd}figcaption{color:#555}"
        "pre{background:#f4f4f4;padding:.6em;overflow-x:auto}</style></head><body>",
    ]
    for kind, payload in blocks:
        if kind in ("h1", "h2", "p"):
            out.append(f"<{kind}>{html.escape(str(payload))}</{kind}>")
        elif kind == "pre":
            out.append(f"<pre>{html.escape(str(payload))}</pre>")
        elif kind == "banner":
            good, text = payload
            out.append(f'<p class="{"good" if good else "bad"}">{html.escape(text)}</p>')
        elif kind == "table":
            headers, rows, marked = payload
            out.append("<table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in headers) + "</tr>")
            for i, row in enumerate(rows):
                css = ' class="mark"' if i in marked else ""
                out.append(f"<tr{css}>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>")
            out.append("</table>")
        elif kind == "figure":
            name, caption = payload
            data = base64.b64encode(figures[name]).decode("ascii")
            out.append(
                f'<figure><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}">'
                f"<figcaption>{html.escape(caption)}</figcaption></figure>"
            )
    out.append("</body></html>")
    return "\n".join(out) + "\n"


def _md_cell(text: str) -> str:
    return text.replace("|", "\\|")


def render_markdown(blocks: list[Block], figure_dir: str) -> str:
    """Markdown page; pictures are linked from `figure_dir` (relative to the page)."""
    out = []
    for kind, payload in blocks:
        if kind == "h1":
            out.append(f"# {payload}")
        elif kind == "h2":
            out.append(f"## {payload}")
        elif kind == "p":
            out.append(str(payload))
        elif kind == "pre":
            out.append(f"```\n{payload}\n```")
        elif kind == "banner":
            good, text = payload
            out.append(f"> **{'OK' if good else 'REFUSED'}**: {text}")
        elif kind == "table":
            headers, rows, marked = payload
            lines = [
                "| " + " | ".join(_md_cell(h) for h in headers) + " |",
                "|" + "|".join(["---"] + ["---:"] * (len(headers) - 1)) + "|",
            ]
            for i, row in enumerate(rows):
                cells = [_md_cell(c) for c in row]
                if i in marked:
                    cells[0] = f"**{cells[0]}**"
                lines.append("| " + " | ".join(cells) + " |")
            out.append("\n".join(lines))
        elif kind == "figure":
            name, caption = payload
            out.append(f"![{caption}]({figure_dir}/{name})\n\n*{caption}*")
    return "\n\n".join(out) + "\n"
