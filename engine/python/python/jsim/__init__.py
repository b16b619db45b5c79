"""jsim — the JASMINE image simulator and ePSF astrometry explorer, from Python.

The Rust engine with numpy arrays in and out; every number comes from the engine (the same images and
analyses as the ``jsim`` command line for the same configuration and seed).

>>> import jsim
>>> cfg = jsim.Config.default()
>>> cfg.set("scene.mag_hw", 12.5)
>>> s = jsim.Session(cfg)
>>> exp = s.simulate(image=0)          # exp.image: uint16 ADU, shape (ny, nx), exp.image[y, x]
>>> rep = s.analyze(exp, countermeasure="none")
>>> rep.summary["accuracy_mas"]

Units are in the names: ``_mas`` milliarcseconds, ``_px`` pixels (0-based, integer = pixel centre),
``_s`` seconds, ``_e`` electrons. Long calls release the GIL and can be stopped with Ctrl-C between
images.
"""

import os as _os
import tempfile as _tempfile

# Mesa's Vulkan loader prints "XDG_RUNTIME_DIR is invalid or not set" when the engine probes for a GPU
# without a session directory: harmless but alarming. The check is only that the variable names an absolute
# path, so point it at the system temporary directory (as the jsim CLI does) — nothing is created, nothing
# left behind — only when none is set.
if not _os.environ.get("XDG_RUNTIME_DIR"):
    _os.environ["XDG_RUNTIME_DIR"] = _tempfile.gettempdir()

from ._jsim import (  # noqa: F401, E402
    COUNTERMEASURES,
    Analysis,
    Config,
    Exposure,
    Session,
    __version__,
    box_least_squares,
    score,
    solve,
    solve_sequence,
    transit,
    transit_flux,
)
from ._jsim import experiment as _experiment  # noqa: E402

__all__ = [
    "COUNTERMEASURES",
    "Analysis",
    "Config",
    "Exposure",
    "Session",
    "box_least_squares",
    "experiment",
    "score",
    "solve",
    "solve_sequence",
    "transit",
    "transit_flux",
    "__version__",
]


def experiment(
    config=None,
    *,
    aces=None,
    readouts=None,
    mags=None,
    countermeasures=None,
    progress=None,
    as_frame=None,
):
    """The paper's experiment: accuracy against magnitude per ACE case, readout order and countermeasure.

    Runs what ``jsim experiment`` runs and returns its rows (the columns of ``experiment.csv``:
    ``ace, readout, countermeasure, mag, accuracy_mas, sem_mas, crlb_mas, predicted_mas, n_images,
    time_s``). Defaults as the CLI: ``aces=["gaussian", "realistic"]``, ``readouts=["rolling"]``,
    ``mags=[12, 12.5, 13, 13.5, 14, 14.5]``, ``countermeasures="none,yzones"`` (a comma-separated str
    or a list; see ``jsim.COUNTERMEASURES``).

    ``progress(done, total)`` is called after each image; Ctrl-C stops between images.

    ``as_frame``: ``None`` (default) returns a pandas DataFrame when pandas is installed, else a dict of
    numpy arrays; ``True`` requires pandas; ``False`` always returns the dict.
    """
    rows = _experiment(
        config,
        aces=aces,
        readouts=readouts,
        mags=mags,
        countermeasures=countermeasures,
        progress=progress,
    )
    if as_frame is False:
        return rows
    try:
        import pandas
    except ImportError:
        if as_frame:
            raise
        return rows
    return pandas.DataFrame(rows)
