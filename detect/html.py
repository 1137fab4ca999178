"""What every quadfdi HTML page shares: the plotting library written once beside the pages, the
page frame, escaping, and figure data embedded as JSON.

The pages draw with plotly.js, the copy that the ``plotly`` Python package ships
(``plotly.offline.get_plotlyjs``): one file, ``plotly.min.js``, written once into the output folder
and referenced relatively by every page, so that a folder of pages opens from disk with no network
and costs the library once, not once per flight. Figures are plain plotly.js JSON (the Python
package's figure classes are not used: they validate every point, which costs seconds on a long
flight), drawn with SVG traces (``scatter``, never ``scattergl``: no GPU needed).
"""

from __future__ import annotations

import html
import json
import math
from pathlib import Path

from quadfdi.core.atomic import write_text

PLOTLY_JS = "plotly.min.js"
CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",sans-serif;margin:1.2em 2em;color:#222;font-size:14px}
h1{font-size:1.35em;margin:0.2em 0} h2{font-size:1.15em;margin-top:1.4em} h3{font-size:1.0em}
table{border-collapse:collapse;margin:0.5em 0} th,td{border:1px solid #ccc;padding:3px 7px;text-align:left}
th{background:#f2f2f2} td.num{text-align:right;font-variant-numeric:tabular-nums}
.muted{color:#777} .alarm{color:#b00020;font-weight:600} .ok{color:#17702a} .refused{color:#8a5a00}
.facts td:first-child{font-weight:600} th.sortable{cursor:pointer} th.sortable:after{content:" \\2195";color:#aaa}
img{max-width:100%}
.evidence{border-left:4px solid #b00020;padding-left:1em;margin:1em 0}
"""


def esc(text) -> str:
    return html.escape("" if text is None else str(text), quote=True)


def write_plotly_js(folder: Path) -> Path:
    """``folder/plotly.min.js`` from the installed plotly package (rewritten only when it differs)."""
    from plotly.offline import get_plotlyjs

    js = get_plotlyjs()
    path = folder / PLOTLY_JS
    if not path.is_file() or path.stat().st_size != len(js.encode()) or path.read_text()[:200] != js[:200]:
        write_text(path, js)
    return path


def json_script(element_id: str, data) -> str:
    """``data`` as a JSON script element (no ``</`` can end it early; NaN written as null)."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    return f'<script type="application/json" id="{esc(element_id)}">{text}</script>'


def rounded(values, digits: int = 4) -> list:
    """A list of floats with ``digits`` significant digits (None for NaN / inf): what a plot needs,
    a third of the bytes of full precision."""
    out = []
    for v in values:
        v = float(v)
        out.append(float(f"{v:.{digits}g}") if math.isfinite(v) else None)
    return out


def page(title: str, body: str, script_src: str | None = None, script: str = "") -> str:
    """A whole HTML page: ``script_src`` (the plotting library, relative) loaded before ``script``."""
    lib = f'<script src="{esc(script_src)}"></script>' if script_src else ""
    tail = f"<script>{script}</script>" if script else ""
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{esc(title)}</title><link rel=\"icon\" href=\"data:,\">"
            f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><style>{CSS}</style>{lib}"
            f"</head><body>\n{body}\n{tail}</body></html>\n")


def fmt(x, nd: int = 1, none: str = "\u2014") -> str:
    return none if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{nd}f}"
