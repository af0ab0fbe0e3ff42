"""Reports: one list of blocks (headings, paragraphs, tables, figures) written as Markdown and
as a self-contained HTML page (figures embedded), so either can be mailed or archived."""

from __future__ import annotations

import base64
import html
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass
class Report:
    """Blocks in order; ``write(dir)`` writes ``report.md`` and ``report.html`` there.

    Figures are paths; in Markdown they are linked relative to the report's directory.
    """

    title: str
    blocks: list[tuple[str, Any]] = field(default_factory=list)

    def heading(self, text: str, level: int = 2) -> None:
        self.blocks.append(("heading", (level, text)))

    def text(self, text: str) -> None:
        self.blocks.append(("text", text))

    def table(self, headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> None:
        self.blocks.append(("table", (list(headers), [[_cell(c) for c in r] for r in rows])))

    def figure(self, path: str | Path, caption: str) -> None:
        self.blocks.append(("figure", (Path(path), caption)))

    def markdown(self, base: Path) -> str:
        out = [f"# {self.title}", ""]
        for kind, value in self.blocks:
            if kind == "heading":
                out += ["#" * value[0] + " " + value[1], ""]
            elif kind == "text":
                out += [value, ""]
            elif kind == "table":
                headers, rows = value
                out.append("| " + " | ".join(headers) + " |")
                out.append("|" + "---|" * len(headers))
                out += ["| " + " | ".join(r) + " |" for r in rows]
                out.append("")
            else:
                path, caption = value
                full = path.resolve()
                rel = full.relative_to(base) if full.is_relative_to(base) else full
                out += [f"![{caption}]({rel.as_posix()})", "", f"*{caption}*", ""]
        return "\n".join(out)

    def html(self) -> str:
        parts = [
            "<!doctype html><html><head><meta charset='utf-8'>",
            f"<title>{html.escape(self.title)}</title><style>"
            "body{font-family:sans-serif;max-width:72em;margin:2em auto;line-height:1.45}"
            "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;"
            "padding:.25em .6em;text-align:right}th{background:#eee}img{max-width:100%}"
            "figcaption{font-style:italic;color:#444}</style></head><body>",
            f"<h1>{html.escape(self.title)}</h1>",
        ]
        for kind, value in self.blocks:
            if kind == "heading":
                parts.append(f"<h{value[0]}>{html.escape(value[1])}</h{value[0]}>")
            elif kind == "text":
                parts.append(f"<p>{html.escape(value)}</p>")
            elif kind == "table":
                headers, rows = value
                parts.append(
                    "<table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in headers) + "</tr>"
                )
                parts += [
                    "<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>"
                    for r in rows
                ]
                parts.append("</table>")
            else:
                path, caption = value
                data = base64.b64encode(path.read_bytes()).decode("ascii")
                parts.append(
                    f"<figure><img src='data:image/png;base64,{data}' "
                    f"alt='{html.escape(caption)}'><figcaption>"
                    f"{html.escape(caption)}</figcaption></figure>"
                )
        parts.append("</body></html>")
        return "\n".join(parts)

    def write(self, out_dir: str | Path) -> tuple[Path, Path]:
        base = Path(out_dir)
        base.mkdir(parents=True, exist_ok=True)
        md, page = base / "report.md", base / "report.html"
        md.write_text(self.markdown(base.resolve()) + "\n", encoding="utf-8")
        page.write_text(self.html() + "\n", encoding="utf-8")
        return md, page


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return "n/a" if value != value else f"{value:.3f}"
    return str(value)
