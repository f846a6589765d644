"""The examples gallery: every figure is produced by running the code shown beside it, when
the site is built (called by ``docs/hooks.py``).

Entries:

* the snippets in :data:`SNIPPETS` (Python, run in a temporary directory, in this process);
* every ``examples/*.py`` script, run as ``python examples/NAME.py --output-dir DIR`` (its
  printed output and the PNG files it writes are shown; its module docstring is the text);
* every ``examples/*.toml`` file, run with the commands its leading comments give (comment lines
  whose text starts with ``slipstep ``, in backticks or not; a trailing backslash continues the
  command), in an empty directory; without any, as ``slipstep run`` followed by ``slipstep plot``.
  Every PNG file the commands write is shown.

An example that fails fails the build (``mkdocs build --strict`` then stops), so the gallery
cannot show a figure the code no longer makes. Keep examples short: the gallery runs them all
(the scripts and case files in subprocesses, one per CPU at a time, beside the snippets).

    python docs/gen_gallery.py OUT_DIR     # write the gallery pages and figures to OUT_DIR
"""

from __future__ import annotations

import ast
import contextlib
import io
import os
import re
import shlex
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"
EXAMPLES = ROOT / "examples"
if str(SRC) not in sys.path:
    sys.path.insert(0, str(SRC))

TIMEOUT_S = 300

# (slug, title, text, code): the code runs in an empty directory and writes the PNG files shown
SNIPPETS = [
    (
        "paper_case",
        "The paper's damper: time histories, loops and contact states",
        "The built-in case `paper` (Gastaldi & Berruti 2018, Fig. 7): a wedge damper between two platforms, the "
        "right one moving 25 um at 200 Hz. Method 3 (piecewise-linear Newmark) against the quasi-static march "
        "(Method 4); the hysteresis loops of each platform interface, raw and after the paper's low-pass filter; "
        "the contact state of each point over the last period.",
        """\
import warnings

import slipstep as ss
from slipstep.post import plots
system = ss.load_system("paper")
ds = ss.run(system, "piecewise-linear", periods=3, step_rule="t-min")  # the paper's steps
reference = ss.run(system, "quasi-static", periods=3)
with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # the filter warns only when it cannot separate the ringing
    filtered = ss.post.filter_dataset(ds, system)

plots.save_figure(plots.plot_time_histories([reference, ds]), "time_histories.png")
plots.save_figure(plots.plot_loops(ds, filtered, interfaces=system), "interface_loops.png")
plots.save_figure(plots.plot_state_timeline(ds), "states.png")
print(ss.post.loop_summary(ds, system).interface_energy_J.to_series())
""",
    ),
    (
        "method_comparison",
        "The paper's methods side by side (Figures 5 and 8)",
        "`slipstep compare paper` in Python, on one period with one timing run (the numbers in the README are "
        "medians of 9 runs over 3 periods): the kernel time of each method relative to Method 1 (the paper's "
        "Figure 8) and the linear solves per step of Method 1 and Method 3 (Figure 5). Timings are those of the "
        "machine that built this page.",
        """\
import slipstep as ss
from slipstep.study.compare import compare, write_outputs

system = ss.load_system("paper")
datasets = {}
rows = compare(system, periods=1, repeats=1, datasets=datasets)
write_outputs(rows, datasets, ".", title="paper case, 1 period")
for row in rows:
    print(f"{row['paper_method']:>10}  time ratio {row['time_ratio']:.2f}  steps {row['steps']:4d}  solves {row['solves']:5d}")
""",
    ),
]


def _module_doc(path: Path) -> str:
    return ast.get_docstring(ast.parse(path.read_text())) or ""


def _toml_commands(path: Path) -> list[str]:
    """The commands a TOML file's leading comments give for itself: comment lines whose text (in
    backticks or not) starts with ``slipstep ``, a trailing backslash continuing on the next line,
    a shell comment (`` # ...``) after the command dropped."""
    commands: list[str] = []
    pending = ""
    for line in path.read_text().splitlines():
        if not line.startswith("#"):
            break
        text = line.lstrip("#").strip().strip("`").strip()
        if pending:
            pending += " " + text
        elif text.startswith("slipstep "):
            pending = text
        else:
            continue
        if pending.endswith("\\"):
            pending = pending[:-1].rstrip()
        else:
            commands.append(shlex.join(shlex.split(pending, comments=True)))  # a trailing `# note` is not an argument
            pending = ""
    return commands


GALLERY_SAMPLES = 3  # random samples per level of a Monte Carlo sweep run for the gallery


def _gallery_copy(path: Path, workdir: Path) -> tuple[Path, str]:
    """(the TOML file the gallery runs, a note for the page): a sweep with random samples
    (``samples = N`` in a [[parameter]] table, N > GALLERY_SAMPLES) runs from a copy with
    GALLERY_SAMPLES samples per level, so the site builds in minutes (the full study is the
    file as written, timed by its benchmark); any other file runs as it is."""
    text = path.read_text()
    reduced, count = re.subn(r"(?m)^(samples\s*=\s*)(\d+)", lambda m: _fewer_samples(m), text)
    if count == 0 or reduced == text:
        return path, ""
    copy = workdir / path.name
    copy.write_text(reduced)
    return copy, f"(run here with samples = {GALLERY_SAMPLES} per level; the file asks for more)\n"


def _fewer_samples(match: re.Match) -> str:
    return match.group(1) + str(min(int(match.group(2)), GALLERY_SAMPLES))


def _toml_title(path: Path) -> str:
    """A TOML file's ``description`` (or ``[sweep] description``), else its name."""
    from slipstep.casefile.case import read_toml  # tomllib, or tomli on Python 3.10

    data = read_toml(path)
    text = data.get("description") or data.get("sweep", {}).get("description") or path.stem.replace("_", " ")
    return text[:1].upper() + text[1:]


def _toml_comment(path: Path) -> str:
    """The prose of a TOML file's leading comments (the command lines left out)."""
    prose, continued = [], False
    for line in path.read_text().splitlines():
        if not line.startswith("#"):
            break
        text = line.lstrip("#").strip()
        command = continued or text.strip("`").startswith("slipstep ")
        continued = command and text.endswith("\\")
        if text and not command:
            prose.append(text)
    return " ".join(prose)


@contextlib.contextmanager
def _in_directory(path: Path):
    old = Path.cwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(old)


def _run_snippet(code: str, workdir: Path) -> str:
    import matplotlib

    matplotlib.use("Agg")
    buffer = io.StringIO()
    with _in_directory(workdir), contextlib.redirect_stdout(buffer):
        exec(compile(code, "<gallery>", "exec"), {"__name__": "__gallery__"})
    import matplotlib.pyplot as plt

    plt.close("all")
    return buffer.getvalue()


def _env() -> dict:
    env = dict(os.environ, MPLBACKEND="Agg")
    env["PYTHONPATH"] = os.pathsep.join([str(SRC)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    return env


def _run(args: list[str], workdir: Path) -> str:
    proc = subprocess.run(args, cwd=workdir, env=_env(), capture_output=True, text=True, timeout=TIMEOUT_S)
    if proc.returncode != 0:
        raise RuntimeError(f"gallery example {' '.join(args)} failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
    return proc.stdout


def _slipstep(*args: str) -> list[str]:
    return [
        sys.executable,
        "-c",
        "import sys; from slipstep.cli.main import app; sys.argv[0] = 'slipstep'; app()",
        *args,
    ]


def _page(
    title: str, text: str, code: str, lang: str, output: str, figures: list[str], seconds: float, source: str = ""
) -> str:
    L = [f"# {title}", "", text, ""]
    if source:
        L += [source, ""]
    L += [f"```{lang}", code.rstrip(), "```", ""]
    if output.strip():
        L += ["Output:", "", "```text", output.rstrip(), "```", ""]
    for fig in figures:
        L += [f"![{Path(fig).stem.replace('_', ' ')}]({fig})", ""]
    L += [f"*Produced by running the code above when this site was built ({seconds:.1f} s).*", ""]
    return "\n".join(L)


# (slug, title, text, commands): command-line runs of built-in cases, each in an empty directory
COMMANDS = [
    (
        "blades_frf",
        "Forced response of two blades with the paper's damper",
        "The built-in assembly `blades`: two Craig-Bampton reduced frame blades with the paper's underplatform "
        "damper between their platforms, driven out of phase at the tips. `slipstep frf` sweeps the excitation "
        "frequency up and down, each point a periodic steady state found by shooting (Newton on the one-period "
        "map; Floquet multipliers beyond 1 mark unstable orbits), beside the two linear limits (damper removed, "
        "damper stuck), with the friction energy dissipated per cycle in each contact.",
        ["slipstep frf blades -f 150:450:31 --solver shoot --direction both"],
    ),
]

NAV_TITLES = {
    "paper_case": "The paper's damper",
    "method_comparison": "Methods side by side",
    "blades_frf": "Blades: forced response",
}


def _entries() -> list[tuple[str, str]]:
    """(slug, title) of every gallery entry, in page order."""
    out = [(slug, title) for slug, title, _, _ in SNIPPETS]
    out += [(slug, title) for slug, title, _, cmds in COMMANDS if _command_available(cmds)]
    for path in sorted(EXAMPLES.glob("*.py")):
        out.append(
            (path.stem, " ".join(_module_doc(path).split("\n\n")[0].split()).split(": ")[0].rstrip(".") or path.stem)
        )
    for path in sorted(EXAMPLES.glob("*.toml")):
        out.append((path.stem, _toml_title(path)))
    return out


def _command_available(commands: list[str]) -> bool:
    """Whether the CLI of this tree has the subcommands used (a tree without `slipstep frf` skips the entry)."""
    import typer

    from slipstep.cli.main import app

    known = set(typer.main.get_command(app).commands)
    return all(shlex.split(c)[1] in known for c in commands)


def gallery_nav() -> list:
    """The mkdocs nav of the gallery: the index, then one page per entry."""
    toml = {p.stem for p in EXAMPLES.glob("*.toml")}
    return ["gallery/index.md"] + [
        {NAV_TITLES.get(slug, slug.replace("_", " ").capitalize() if slug in toml else title): f"gallery/{slug}.md"}
        for slug, title in _entries()
    ]


def gallery_pages(run: bool = True) -> dict[str, str | bytes]:
    """{"gallery/...": Markdown or PNG bytes}: the index page, one page per entry, its figures."""
    pages: dict[str, str | bytes] = {}
    index = [
        "# Examples gallery",
        "",
        "Each page shows the code, what it printed and the figures it wrote, all produced by running it when "
        "this site was built (`docs/gen_gallery.py`). The scripts and case files are in `examples/`.",
        "",
    ]
    for slug, title in _entries():
        index.append(f"- [{title}]({slug}.md)")
    pages["gallery/index.md"] = "\n".join(index) + "\n"
    if not run:
        for slug, title in _entries():
            pages[f"gallery/{slug}.md"] = f"# {title}\n\nThe gallery was built with SLIPSTEP_DOCS_GALLERY=0: not run.\n"
        return pages
    jobs = []  # (in this process, slug, make, page)
    for slug, title, text, code in SNIPPETS:
        jobs.append(
            (
                True,
                slug,
                lambda d, c=code: _run_snippet(c, d),
                lambda out, figs, s, t=title, x=text, c=code: _page(t, x, c, "python", out, figs, s),
            )
        )
    for slug, title, text, cmds in COMMANDS:
        if not _command_available(cmds):
            continue
        jobs.append(
            (
                False,
                slug,
                lambda d, c=tuple(cmds): "".join(_run(_slipstep(*shlex.split(x)[1:]), d) for x in c),
                lambda out, figs, s, t=title, x=text, c=cmds: _page(t, x, "\n".join(c), "bash", out, figs, s),
            )
        )
    for path in sorted(EXAMPLES.glob("*.py")):
        first, _, rest = _module_doc(path).partition("\n\n")
        title, _, lead = " ".join(first.split()).partition(": ")
        rest = (lead[:1].upper() + lead[1:] + "\n\n" if lead else "") + rest
        jobs.append(
            (
                False,
                path.stem,
                lambda d, p=path: _run([sys.executable, str(p), "--output-dir", str(d)], d).replace(str(d), "DIR"),
                lambda out, figs, s, p=path, t=title, r=rest: _page(
                    t.rstrip("."),
                    "\n\n".join(
                        " ".join(par.split()) for par in r.split("\n\n") if par.strip() and not par.startswith("    ")
                    ),
                    f"python examples/{p.name} --output-dir DIR",
                    "bash",
                    out,
                    figs,
                    s,
                    source=f"Source: `examples/{p.name}`.",
                ),
            )
        )
    for path in sorted(EXAMPLES.glob("*.toml")):
        own = _toml_commands(path)
        if own:  # the file names the commands that show it (`slipstep frf ...`, `slipstep sweep ...`)
            commands = "\n".join(own)

            def run_case(d: Path, p=path, cmds=tuple(own)) -> str:
                spec, text = _gallery_copy(p, d)
                for cmd in cmds:
                    args = [str(spec) if a == f"examples/{p.name}" else a for a in shlex.split(cmd)[1:]]
                    text += _run(_slipstep(*args), d)
                return text.replace(str(d) + os.sep, "")

        else:
            commands = (
                f"slipstep run examples/{path.name} --output-dir DIR\n"
                f"slipstep plot DIR/RESULT.nc -o DIR --case examples/{path.name}"
            )

            def run_case(d: Path, p=path) -> str:
                text = _run(_slipstep("run", str(p), "--output-dir", str(d)), d)
                results = sorted(d.glob("*.nc"))
                if not results:
                    raise RuntimeError(f"gallery: `slipstep run {p}` wrote no result")
                text += _run(_slipstep("plot", str(results[0]), "--output-dir", str(d), "--case", str(p)), d)
                for png in d.glob("*.png"):  # the figures that read best on a page
                    if not png.stem.endswith(("time_histories", "loops", "states")):
                        png.unlink()
                return text.replace(str(d) + os.sep, "")

        jobs.append(
            (
                False,
                path.stem,
                run_case,
                lambda out, figs, s, p=path, c=commands: _page(
                    f"{_toml_title(p)} (`examples/{p.name}`)",
                    _toml_comment(p),
                    c,
                    "bash",
                    out,
                    figs,
                    s,
                    source=f"```toml\n{p.read_text().rstrip()}\n```",
                ),
            )
        )
    pages.update(_run_all(jobs))
    return pages


def _run_all(jobs) -> dict[str, str | bytes]:
    """The pages of ``jobs`` [(in this process, slug, make, page)], in their order. The entries
    that run in subprocesses go through a pool of one thread per CPU while this thread runs the
    in-process snippets (which change the working directory, so one at a time): the gallery is
    most of the build's time, and the CI machine has two cores."""
    workers = max(1, os.cpu_count() or 1)
    with ThreadPoolExecutor(max_workers=workers) as pool:
        pending = [None if here else pool.submit(_build, slug, make, page) for here, slug, make, page in jobs]
        built = [_build(slug, make, page) if here else None for here, slug, make, page in jobs]
        built = [b if f is None else f.result() for b, f in zip(built, pending)]
    return {uri: content for pages in built for uri, content in pages.items()}


def _build(slug: str, make, page) -> dict[str, str | bytes]:
    with tempfile.TemporaryDirectory(prefix=f"slipstep-gallery-{slug}-") as tmp:
        d = Path(tmp)
        start = time.perf_counter()
        output = make(d)
        seconds = time.perf_counter() - start
        figures = sorted(d.rglob("*.png"), key=lambda f: (f.stat().st_mtime_ns, f.name))  # the order written
        if not figures:
            raise RuntimeError(f"gallery entry {slug!r} wrote no figure")
        names = [f.relative_to(d).as_posix().replace("/", "_") for f in figures]
        out = {f"gallery/{slug}/{n}": f.read_bytes() for f, n in zip(figures, names)}
        out[f"gallery/{slug}.md"] = page(output, [f"{slug}/{n}" for n in names], seconds)
    return out


if __name__ == "__main__":  # pragma: no cover
    target = Path(sys.argv[1] if len(sys.argv) > 1 else "gallery-out")
    for rel, content in gallery_pages().items():
        path = target / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(content) if isinstance(content, bytes) else path.write_text(content)
    print(f"wrote the gallery to {target}")
