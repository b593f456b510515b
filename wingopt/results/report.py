"""A single self-contained HTML report: inline CSS, figures embedded as base64 PNG, no scripts.

Opening it needs nothing but a browser, offline, and it renders without console errors.
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["Report", "figure_png"]

_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto; max-width: 1100px;
       color: #1d2330; line-height: 1.45; padding: 0 1em; }
h1 { border-bottom: 3px solid #2b6cb0; padding-bottom: .3em; }
h2 { margin-top: 2em; color: #2b6cb0; }
table { border-collapse: collapse; margin: 1em 0; font-size: 0.92em; }
th, td { border: 1px solid #cbd5e0; padding: .35em .7em; text-align: right; }
th { background: #edf2f7; }
td:first-child, th:first-child { text-align: left; }
caption { caption-side: top; text-align: left; font-weight: 600; padding-bottom: .3em; }
figure { margin: 1.5em 0; }
figure img { max-width: 100%; border: 1px solid #e2e8f0; }
figcaption { font-size: 0.9em; color: #4a5568; }
.note { background: #f7fafc; border-left: 4px solid #a0aec0; padding: .5em 1em; }
.ok { color: #276749; } .bad { color: #c53030; }
"""


def figure_png(fig, dpi: int = 110) -> bytes:
    """PNG bytes of a matplotlib figure (a pyplot-managed figure is closed afterwards)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    if getattr(fig.canvas, "manager", None) is not None:  # made by pyplot: release it
        import matplotlib.pyplot as plt

        plt.close(fig)
    return buf.getvalue()


def _cell(v) -> str:
    if isinstance(v, float):
        return html.escape(f"{v:.4g}")
    return html.escape(str(v))


@dataclass
class Report:
    """Build a report section by section, then :meth:`write` it."""

    title: str
    parts: list[str] = field(default_factory=list)

    def heading(self, text: str, level: int = 2) -> Report:
        self.parts.append(f"<h{level}>{html.escape(text)}</h{level}>")
        return self

    def paragraph(self, text: str, css_class: str | None = None) -> Report:
        cls = f' class="{css_class}"' if css_class else ""
        self.parts.append(f"<p{cls}>{html.escape(text)}</p>")
        return self

    def table(self, header: Sequence[str], rows: Sequence[Sequence], caption: str = "") -> Report:
        out = ["<table>"]
        if caption:
            out.append(f"<caption>{html.escape(caption)}</caption>")
        out.append("<tr>" + "".join(f"<th>{html.escape(str(h))}</th>" for h in header) + "</tr>")
        for r in rows:
            out.append("<tr>" + "".join(f"<td>{_cell(v)}</td>" for v in r) + "</tr>")
        out.append("</table>")
        self.parts.append("\n".join(out))
        return self

    def warnings(self, items: Sequence[tuple[str, str]]) -> Report:
        """The runs' warnings (``(run, warning)`` pairs), or a line saying there are none."""
        if not items:
            return self.paragraph("Warnings: none (the warnings list of summary.json is empty).", "ok")
        lis = "".join(f"<li><b>{html.escape(run)}</b>: {html.escape(w)}</li>" for run, w in items)
        self.parts.append(f'<div class="note bad"><p>Warnings ({len(items)}):</p><ul>{lis}</ul></div>')
        return self

    def figure(self, png: bytes | Path, caption: str = "") -> Report:
        """Embed a PNG (bytes or a file path) as a data URI."""
        data = Path(png).read_bytes() if isinstance(png, (str, Path)) else png
        uri = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
        cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
        self.parts.append(f'<figure><img src="{uri}" alt="{html.escape(caption)}">{cap}</figure>')
        return self

    def render(self) -> str:
        body = "\n".join(self.parts)
        return (
            '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
            f"<title>{html.escape(self.title)}</title>\n<style>{_CSS}</style>\n"
            '<link rel="icon" href="data:,">\n</head>\n'
            f"<body>\n<h1>{html.escape(self.title)}</h1>\n{body}\n</body>\n</html>\n"
        )

    def write(self, path: Path) -> Path:
        path = Path(path)
        path.write_text(self.render(), encoding="utf-8")
        return path
