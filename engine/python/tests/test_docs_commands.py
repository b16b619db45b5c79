"""Every command README.md and docs/*.md show runs, as written but reduced.

The commands are read from the Markdown itself (code blocks, and inline code that is a whole command), so a page
that gains a command gains a test. Templates — a command with a placeholder such as `DIR`, `F.fits`, `…` or
`$SLURM_ARRAY_TASK_ID` — and bare mentions (`jsim analyze`) are not commands and are left out; optional parts in
brackets are dropped. They run in one scratch directory laid out like the repository (its catalogues, configs, sequence files,
sweep files and Python scripts), producers before consumers, each one exactly as written except for the
reductions below, which make the whole page set run in a few minutes:

* every command that simulates (or reads a configuration to predict) gets `--set` overrides for a 256-px array, a 4 × 4 grid, coarse
  optics and 2 images (`REDUCED`; a command's own `--images` is capped at 2), except for the keys the command sets
  itself;
* `jsim bench` gets `--quick` and small star counts (its own star-count and solution-size options are replaced);
* `jsim sequence` runs at most 2 exposures (`--exposures`; its Slurm scripts are only written), and `jsim solve`
  solves those (`--exposures 1,2`);
* `jsim solve-synthetic` solves 300 sources × 25 exposures;
* `jsim transit` stares at most 0.4 h with 3 comparison stars at a 2-day period (a transit shorter than the
  stare), and its precision study takes two magnitudes of 0.15 h;
* `jsim bench --parts persistence` runs `--quick` (stares of 4 exposures) like every bench;
* the sweep files are copied with the same reduced `[base]`, 2 exposures in one stare, and each grid axis cut
  to its first and last value;
* `crowded_image.py` writes a 256-px array of 1500 stars instead of 1968 px and 10⁵ stars,
  `photutils_catalogue.py` cuts 128 px instead of 512, `crowded_photutils.py` 128 px with one pass of finding, and `simulate_reference.py` runs the reduced configuration
  once (`--config`, `--repeat 1`) with the jsim binary under test;
* an absolute output path (`/shared/…`) is taken inside the scratch directory;
* a command that writes to its default output directory, where nothing reads it (`jsim experiment`, `crowded`,
  `bench`, …), is given one of its own (`--out out/NAME-K`).

Commands run side by side on `JSIM_DOCS_WORKERS` processes (default 2: CI's two cores; most commands use about
one): a command waits only for the earlier commands that share a place with it — a path under `out/` that either
names (to its second component), or a command's default output — so producers still run before consumers and
two writers of one directory in the pages' order.
"""

import concurrent.futures
import glob
import os
import re
import shlex
import shutil
import subprocess
import sys
import threading
import time
import tomllib

import pytest

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))

REDUCED = {
    "instrument.detector_px": "256",
    "instrument.photosensitive_px": "240",
    "readout.channels": "2",
    "readout.channel_width_px": "128",
    "scene.grid_n": "4",
    "scene.grid_spacing_px": "50.0",
    "optics.pupil_samples": "64",
    "optics.psf_oversampling": "8",
    "optics.psf_radius_px": "8",
    "band.wavelength_step_um": "0.1",
    "fidelity.images": "2",
    "fidelity.subpixels": "4",
    "fidelity.stamp_radius_px": "8",
    "fidelity.backend": '"cpu"',
    "ace.span_s": "60.0",
}
# the command-line shortcut that sets each reduced key (the command's own value is kept)
SHORTCUT = {"fidelity.images": "--images", "fidelity.backend": "--backend"}
TAKES_SET = {"psf", "ace", "simulate", "experiment", "crowded", "bench", "predict", "sequence", "transit"}
BENCH = {"--quick": None, "--stars": "50,100", "--bulge-stars": "50,100", "--ref-stars": "5",
         "--epsf-images": "1", "--solution-sources": "300", "--solution-exposures": "25,50"}
# a placeholder word (`DIR`, `F.fits`, `fidelity.images=K`, `$VAR`, `…`), or an option in a list (`--a, --b`)
PLACEHOLDER = re.compile(r"(…|<|\$|^[A-Z]{1,4}(\.[a-z]+)?$|=[A-Z]{1,4}$|^(DIR|PATH)$|NNN|^/$|^--[a-z-]+,$)")
# producers before consumers; within a rank, the pages' order
RANK = {"config": 0, "psf": 1, "ace": 1, "predict": 1, "simulate": 2, "crowded_image.py": 3, "crowded": 3,
        "experiment": 4, "bench": 4, "sequence": 4, "transit": 4, "analyze": 5, "solve": 5, "solve-synthetic": 1, "photutils_catalogue.py": 6, "focal_plane_image.py": 6,
        "crowded_photutils.py": 6, "check_real_image.py": 6, "simulate_reference.py": 6, "persistence_cost.py": 6, "score": 7, "sweep": 8, "merge": 9, "report": 10}


def pages():
    return [os.path.join(REPO, "README.md")] + sorted(glob.glob(os.path.join(REPO, "docs", "*.md")))


def commands_in(text):
    """The `jsim …` and `python …` commands of a page: code-block lines (with `\\` continuations) and inline
    code (a span may cross a line break)."""
    out = []
    lines = text.split("\n")
    in_block, prose, i = False, [], 0
    while i < len(lines):
        line = lines[i]
        if line.strip().startswith("```"):
            in_block = not in_block
        elif in_block:
            cmd = line.strip()
            while cmd.endswith("\\") and i + 1 < len(lines):
                i += 1
                cmd = cmd[:-1].strip() + " " + lines[i].strip()
            if cmd.startswith(("jsim ", "python ")):
                out.append(re.sub(r"\s+#.*$", "", cmd))
        else:
            prose.append(line)
        i += 1
    for m in re.finditer(r"`((?:jsim|python) [^`]+)`", " ".join(prose)):
        out.append(m.group(1))
    return out


def runnable(cmd):
    """The command without its optional [parts], or None for a template or a bare mention."""
    cmd = re.sub(r"\s*\[[^\]]*\]", "", cmd).strip()
    words = shlex.split(cmd)
    if len(words) < 3 or any(PLACEHOLDER.search(w) for w in words):
        return None
    return words


def name_of(words):
    return os.path.basename(words[1]) if words[0] == "python" else words[1]


def reduce(words, jsim_bin="jsim"):
    """The command as run here (see the module's documentation)."""
    words = [w[1:] if w.startswith("/shared/") else w for w in words]
    name = name_of(words)
    if words[0] == "python":
        if name == "crowded_image.py":
            k = words.index("--stars")
            words[k + 1:k + 2] = ["1500", "--size", "256", "--mag-min", "11", "--mag-max", "16"]
        if name == "crowded_photutils.py":
            # a 128-px cut of the reduced array (32 isolated stars: photutils 3 builds no ePSF from the 96-px cut's 18),
            # one pass of finding
            if "--size" in words:
                words[words.index("--size") + 1] = "128"
            words += ["--iters", "1"]
        if name == "photutils_catalogue.py":
            words[words.index("--size") + 1] = "128"
        if name == "simulate_reference.py":
            words[words.index("--jsim") + 1] = jsim_bin
            words += ["--config", "small.toml", "--repeat", "1"]
        return [sys.executable] + words[1:]
    if name == "solve-synthetic":
        for opt, value in (("--sources", "300"), ("--exposures", "25")):
            if opt in words:
                words[words.index(opt) + 1] = value
            else:
                words += [opt, value]
    if name == "bench":
        for opt, value in BENCH.items():
            if opt in words:
                if value is not None:
                    words[words.index(opt) + 1] = value
            else:
                words += [opt] if value is None else [opt, value]
    if name == "sequence" and "--plan-only" not in words and "--emit-slurm" not in words:
        # a sequence runs at most 2 of its exposures (each shard its share of them)
        if "--exposures" in words:
            k = words.index("--exposures") + 1
            words[k] = str(min(int(words[k]), 2))
        else:
            words += ["--exposures", "2"]
    if name == "transit":
        # a stare of 3 comparison stars (they fit the reduced array) for 0.4 h, the planet on a 2-day orbit
        # (a 0.25-h transit: the stare must outlast it); the precision study at two magnitudes of 0.15 h
        words += ["--set", "transit.comparisons=3"]
        study = "--magnitudes" in words
        if study:
            k = words.index("--magnitudes") + 1
            words[k] = ",".join(words[k].split(",")[:2])
        else:
            words += ["--set", "transit.period_days=2"]
        hours = "0.15" if study else "0.4"
        if "--hours" in words:
            k = words.index("--hours") + 1
            words[k] = str(min(float(words[k]), float(hours)))
        else:
            words += ["--hours", hours]
    if name == "solve" and "--exposures" in words:
        # the reduced sequence has run 2 exposures
        words[words.index("--exposures") + 1] = "1,2"
    if name in TAKES_SET:
        # a command's own image count is reduced too (the reduced ACE series covers the reduced count)
        if "--images" in words:
            k = words.index("--images") + 1
            if k < len(words) and words[k].isdigit():
                words[k] = str(min(int(words[k]), int(REDUCED["fidelity.images"])))
        given = " ".join(words)
        for key, value in REDUCED.items():
            if key in given or (SHORTCUT.get(key) and SHORTCUT[key] in words):
                continue
            words += ["--set", f"{key}={value}"]
    return words


def toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f'"{k}" = {toml_value(x)}' for k, x in v.items()) + " }"
    return repr(v)


def write_toml(path, data, prefix=""):
    """A nested dict as TOML (scalars, lists, inline tables for lists of tables)."""
    lines, tables = [], []
    for k, v in data.items():
        if isinstance(v, dict):
            tables.append((k, v))
        else:
            lines.append(f'"{k}" = {toml_value(v)}')
    text = "\n".join(lines) + "\n"
    for k, v in tables:
        name = f"{prefix}.{k}" if prefix else k
        text += f"\n[{name}]\n" + write_toml(None, v, name)
    if path is None:
        return text
    with open(path, "w") as f:
        f.write(text)


def reduced_sweep(src, dst):
    with open(src, "rb") as f:
        s = tomllib.load(f)
    s["exposures"], s["stare_exposures"] = 2, 2
    # each grid axis at its two ends (a 3 × 3 × 2 grid is 2 × 2 × 2 points)
    for key, values in s.get("grid", {}).items():
        if isinstance(values, list) and len(values) > 2:
            s["grid"][key] = [values[0], values[-1]]
    base = s.setdefault("base", {})
    for key, value in REDUCED.items():
        table, field = key.split(".")
        if key in s.get("grid", {}):
            continue
        base.setdefault(table, {})[field] = tomllib.loads(f"v = {value}")["v"]
    write_toml(dst, s)


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    """A directory laid out like the repository: catalogues and configs as they are, the sweep files reduced,
    the Python scripts and the test data (real telescope files) linked."""
    d = tmp_path_factory.mktemp("docs")
    for sub in ["catalogues", "configs", "sequences"]:
        shutil.copytree(os.path.join(REPO, "engine", sub), d / "engine" / sub)
    os.makedirs(d / "engine" / "sweeps")
    for f in glob.glob(os.path.join(REPO, "engine", "sweeps", "*.toml")):
        reduced_sweep(f, d / "engine" / "sweeps" / os.path.basename(f))
    os.symlink(os.path.join(REPO, "engine", "python"), d / "engine" / "python")
    os.makedirs(d / "tests")
    os.symlink(os.path.join(REPO, "tests", "data"), d / "tests" / "data")
    small = {}
    for key, value in REDUCED.items():
        table, field = key.split(".")
        small.setdefault(table, {})[field] = tomllib.loads(f"v = {value}")["v"]
    write_toml(d / "small.toml", small)
    return d


def test_the_pages_show_the_commands_this_test_knows():
    found = {name_of(w) for p in pages() for c in commands_in(open(p).read()) if (w := runnable(c))}
    unknown = found - set(RANK)
    assert not unknown, f"commands this test cannot order (add them to RANK): {unknown}"
    # the main jobs are among them: a regression in the extraction would silently drop everything
    assert {"simulate", "analyze", "score", "experiment", "crowded", "sweep", "bench"} <= found, found


# where a command writes when it is given no --out (the CLI's defaults)
DEFAULT_OUT = {"simulate": "out/simulate", "analyze": "out/analyze", "experiment": "out/experiment",
               "sequence": "out/sequence", "solve": "out/sequence", "transit": "out/transit", "crowded": "out/crowded",
               "score": "out/score", "bench": "out/bench", "sweep": "out/sweep", "solve-synthetic": "out/solve-synthetic"}


def places(words):
    """The output places a command touches: each path it names under `out/` (to its second component, where two
    commands can meet), or any other file it writes with --out, and the default output of a command given none.
    Commands that share a place run one after the other, in the pages' order."""
    found = set()
    for w in words:
        w = w.split("=", 1)[-1].lstrip("/")
        parts = w.split("/")
        if parts[0] == "out" and len(parts) > 1:
            found.add("/".join(parts[:2]))
    if "--out" in words:
        out = words[words.index("--out") + 1].lstrip("/")
        found.add("/".join(out.split("/")[:2]))
    elif words[0] == "jsim" and name_of(words) in DEFAULT_OUT and not (
            name_of(words) == "solve" and "--sequence" in words):
        # (a solve writes into its sequence's directory, named above when given)
        found.add(DEFAULT_OUT[name_of(words)])
    return found


# what a script reads when it is given no path (its argparse defaults)
READS = {"crowded_photutils.py": {"out/crowded"}}
# the commands whose default output nothing reads: each is given its own, so that they need not wait on each other
OWN_OUT = {"simulate", "analyze", "experiment", "transit", "crowded", "score", "bench", "solve-synthetic"}


def after(cmds):
    """For each command (in rank order), the earlier commands it waits on: those that share a place with it."""
    owner, deps = {}, []
    for i, (_, words) in enumerate(cmds):
        mine = places(words) | READS.get(name_of(words), set())
        deps.append({owner[p] for p in mine if p in owner})
        for p in mine:
            owner[p] = i
    return deps


def test_commands_that_share_an_output_run_in_order():
    cmds = [("a", ["jsim", "sequence", "--exposures", "3"]),
            ("b", ["jsim", "sequence", "--plan-only", "--out", "out/sequence"]),
            ("c", ["python", "x/photutils_catalogue.py", "--out", "out/hst_photutils"]),
            ("d", ["python", "x/check_real_image.py", "f.fits", "out/hst", "--photutils", "out/hst_photutils/p.csv"]),
            ("e", ["jsim", "crowded", "--save-images", "--out", "out/crowded"]),
            ("f", ["python", "x/crowded_photutils.py", "--size", "0"]),
            ("g", ["jsim", "solve", "--method", "block"]),
            ("h", ["jsim", "solve", "--sequence", "out/two-visits", "--exposures", "24"])]
    assert after(cmds) == [set(), {0}, set(), {2}, set(), {4}, {1}, set()]


# the worker processes that run the commands: CI's two cores (most commands use about one)
WORKERS = int(os.environ.get("JSIM_DOCS_WORKERS", "2"))


def test_every_command_of_the_readme_and_docs_runs(scratch, jsim_bin):
    cmds, seen = [], set()
    for p in pages():
        for c in commands_in(open(p).read()):
            words = runnable(c)
            if words and " ".join(words) not in seen:
                seen.add(" ".join(words))
                cmds.append((os.path.relpath(p, REPO), words))
    env = dict(os.environ, PATH=os.path.dirname(os.path.abspath(jsim_bin)) + os.pathsep + os.environ["PATH"],
               MPLBACKEND="Agg")
    cmds.sort(key=lambda pw: RANK[name_of(pw[1])])
    for k, (page, words) in enumerate(cmds):
        if words[0] == "jsim" and name_of(words) in OWN_OUT and "--out" not in words:
            cmds[k] = (page, words, ["--out", f"out/{name_of(words)}-{k}"])
        else:
            cmds[k] = (page, words, [])
    deps = after([(page, words + extra) for page, words, extra in cmds])
    failed, lock = [], threading.Lock()

    def run_one(k):
        page, words, extra = cmds[k]
        run = reduce(list(words) + extra, jsim_bin)
        if run[0] == "jsim":
            run[0] = jsim_bin
        t0 = time.perf_counter()
        r = subprocess.run(run, cwd=scratch, env=env, capture_output=True, text=True, timeout=600)
        with lock:
            print(f"{time.perf_counter() - t0:6.1f} s  rc {r.returncode}  {page}: {' '.join(words)}", flush=True)
        if r.returncode != 0:
            return f"{page}: {' '.join(words)}\n  ran: {' '.join(run)}\n  {r.stderr.strip()[-800:]}"
        if "--out" in words and name_of(words) != "sweep":
            out = words[words.index("--out") + 1].lstrip("/")
            if not os.path.exists(scratch / out):
                return f"{page}: {' '.join(words)} wrote no {out}"
        return None

    # producers before consumers: a command starts once the earlier commands it shares a place with have ended;
    # the others run side by side, WORKERS at a time, in rank order
    done, running, broken = set(), {}, set()
    with concurrent.futures.ThreadPoolExecutor(max_workers=WORKERS) as pool:
        waiting = list(range(len(cmds)))
        while waiting or running:
            for k in [k for k in waiting if deps[k] & broken]:
                waiting.remove(k)
                broken.add(k)
                failed.append(f"{cmds[k][0]}: {' '.join(cmds[k][1])}: not run, a command it follows failed")
            for k in [k for k in waiting if deps[k] <= done][:WORKERS - len(running)]:
                waiting.remove(k)
                running[pool.submit(run_one, k)] = k
            if not running:
                continue
            ended, _ = concurrent.futures.wait(running, return_when=concurrent.futures.FIRST_COMPLETED)
            for f in ended:
                k = running.pop(f)
                if f.result() is None:
                    done.add(k)
                else:
                    broken.add(k)
                    failed.append(f.result())
    assert not failed, "commands of the pages that do not run:\n" + "\n".join(failed)
    assert len(cmds) >= 30, f"only {len(cmds)} commands found"
