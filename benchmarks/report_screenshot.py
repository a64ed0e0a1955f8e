"""Headless check of the run report: screenshots and an inventory of its sections.

Usage (after ``snakemake --report report.html``)::

    python benchmarks/report_screenshot.py report.html shots/ [--all] [--expect "Stability maps" ...]

Browser: Chromium from Debian (``apt-get install -y chromium``; that is how it was installed on the
test machine, Chromium 156); set ``CHROME`` to use another binary.  No Python browser driver is
needed: the report is Snakemake's single-page app, so the script writes a copy of ``report.html``
with a few lines of JavaScript appended that call the app's own functions (``app.showCategory``,
``app.setView``) once the page has loaded, and lets Chromium's ``--screenshot`` / ``--dump-dom``
capture the result.

Writes ``00_front.png`` (the workflow description), one ``NN_<category>.png`` per section with the
section's menu open and its first result shown (``--all``: one screenshot per result) and
``inventory.json`` (section -> subsection -> results, with MIME types and whether a caption is
set).  Exits 1 if an expected section or any caption is missing.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

#: Sections the report must have (categories of the report() outputs).
EXPECTED = (
    "Musculoskeletal",
    "Patients",
    "Actuator",
    "Cascade",
    "Tables",
    "Stability maps",
    "FEA check",
    "Speed and accuracy",
)
#: Sections another stage adds later; reported, not required.
OPTIONAL: tuple[str, ...] = ()

# the machine's network is closed: no background connections, no updates, no sync, a fresh profile per call
_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--hide-scrollbars",
    "--virtual-time-budget=20000",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def chrome() -> str:
    exe = os.environ.get("CHROME") or next(
        (shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None
    )
    if not exe:
        sys.exit("no Chromium found: apt-get install -y chromium (or set CHROME)")
    return exe


def with_script(report: str, js: str, tmp: Path, name: str) -> Path:
    """A copy of the report with ``js`` run 0.5 s after load (the app renders first)."""
    i = report.rfind("</body>")
    page = (
        report[:i]
        + f"<script>window.addEventListener('load', () => setTimeout(() => {{{js}}}, 500));</script>"
        + report[i:]
    )
    out = tmp / f"{name}.html"
    out.write_text(page, encoding="utf-8")
    return out


def run(exe: str, page: Path, *, screenshot: Path | None = None, size=(1500, 1300)) -> str:
    with tempfile.TemporaryDirectory() as profile:
        args = [exe, *_FLAGS, f"--user-data-dir={profile}", f"--window-size={size[0]},{size[1]}"]
        args += [f"--screenshot={screenshot}"] if screenshot else ["--dump-dom"]
        p = subprocess.run([*args, page.as_uri()], capture_output=True, text=True, timeout=180)
    return p.stdout


def inventory(exe: str, report: str, tmp: Path) -> dict:
    """The report's sections and results, read from the app's own data in the browser."""
    js = (
        "const inv = {}; for (const [c, subs] of Object.entries(categories)) { inv[c] = {};"
        " for (const [s, paths] of Object.entries(subs)) { inv[c][s] = paths.map(p => ({path: p,"
        " mime: results[p].mime_type, caption: (results[p].caption || '').length > 0, rule:"
        " results[p].job_properties.rule})); } }"
        " const pre = document.createElement('pre'); pre.id = 'inventory';"
        " pre.textContent = JSON.stringify(inv); document.body.appendChild(pre);"
    )
    dom = run(exe, with_script(report, js, tmp, "inventory"))
    m = re.search(r'<pre id="inventory">(.*?)</pre>', dom, re.S)
    if not m:
        sys.exit("the report did not render (no inventory in the DOM)")
    import html

    return json.loads(html.unescape(m.group(1)))


def show(path: str, mime: str) -> str:
    """JavaScript that opens a result in the content panel."""
    kind = "img" if mime.startswith("image/") else "html" if mime == "text/html" else None
    if kind is None:  # e.g. netCDF: only its info panel
        return f"app.showResultInfo({json.dumps(path)});"
    return (
        f"app.setView({{content: '{kind}', contentPath: results[{json.dumps(path)}].data_uri,"
        f" resultPath: {json.dumps(path)}}});"
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("report")
    ap.add_argument("outdir")
    ap.add_argument("--all", action="store_true", help="one screenshot per result")
    ap.add_argument("--expect", nargs="*", default=list(EXPECTED))
    a = ap.parse_args(argv)
    exe = chrome()
    out = Path(a.outdir)
    out.mkdir(parents=True, exist_ok=True)
    report = Path(a.report).read_text(encoding="utf-8")
    with tempfile.TemporaryDirectory() as t:
        tmp = Path(t)
        inv = inventory(exe, report, tmp)
        (out / "inventory.json").write_text(json.dumps(inv, indent=1))
        run(exe, with_script(report, "", tmp, "front"), screenshot=(out / "00_front.png").resolve(), size=(1500, 1100))
        k = 0
        for cat, subs in sorted(inv.items()):
            entries = [e for s in subs.values() for e in s]
            targets = entries if a.all else [next((e for e in entries if e["mime"].startswith("image/")), entries[0])]
            for e in targets:
                k += 1
                slug = re.sub(r"[^A-Za-z0-9]+", "_", f"{cat}_{Path(e['path']).name}" if a.all else cat).strip("_")
                # the menu first, then (after React has rendered it) the result
                js = f"app.showCategory({json.dumps(cat)}); setTimeout(() => {{{show(e['path'], e['mime'])}}}, 300);"
                run(exe, with_script(report, js, tmp, f"s{k}"), screenshot=(out / f"{k:02d}_{slug}.png").resolve())
    missing = [c for c in a.expect if c not in inv]
    no_caption = [e["path"] for subs in inv.values() for s in subs.values() for e in s if not e["caption"]]
    for cat, subs in sorted(inv.items()):
        n = sum(len(s) for s in subs.values())
        print(
            f"{cat}: {n} results in {len(subs)} subsection(s): "
            + "; ".join(f"{s}: " + ", ".join(Path(e["path"]).name for e in es) for s, es in subs.items())
        )
    for c in OPTIONAL:
        print(f"{c}: {'present' if c in inv else 'not in this run (optional)'}")
    if missing or no_caption:
        print(f"MISSING sections: {missing}; results without caption: {no_caption}")
        return 1
    print(f"all {len(a.expect)} expected sections present, every result has a caption; screenshots in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
