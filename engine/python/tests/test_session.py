"""The session from Python: reproducibility, errors that name the field, bad arrays refused with
TypeError/ValueError (never a crash), the GIL released and Ctrl-C honoured between images."""

import _thread
import signal
import sys
import threading

import numpy as np
import pytest

import jsim
from conftest import small_config


def test_the_same_seed_gives_the_same_image_and_another_seed_another():
    a = jsim.Session(small_config(), backend="cpu").simulate(0)
    b = jsim.Session(small_config(), backend="cpu").simulate(0)
    np.testing.assert_array_equal(a.image, b.image)
    c = jsim.Session(small_config(seed=7), backend="cpu").simulate(0)
    assert not np.array_equal(a.image, c.image)
    assert c.header["SEED"] == 7


def test_config_round_trips_through_toml(cfg, tmp_path):
    assert jsim.Config.from_toml(cfg.to_toml()) == cfg
    p = tmp_path / "c.toml"
    p.write_text(cfg.to_toml())
    assert jsim.Config.from_toml(p) == cfg
    assert jsim.Config.from_toml(str(p)) == cfg
    assert cfg.get("scene.grid_n") == 8
    cfg.set("ace.modes.0.freq_hz", 25)
    assert cfg.get("ace.modes.0.freq_hz") == 25.0


def test_the_default_is_the_instrument_as_built_and_as_designed_is_the_control():
    built = jsim.Config.default()
    assert built.get("as_built.wavefront_rms_nm") == 30.0
    design = built.as_designed()
    for field in ("wavefront_rms_nm", "focus_breathing_nm", "distortion_px", "gain_error", "roll_offset_arcsec"):
        assert design.get(f"as_built.{field}") == 0.0, field
    assert design.get("as_built.seed") == built.get("as_built.seed")
    assert built.get("as_built.wavefront_rms_nm") == 30.0  # a copy: the original is unchanged
    # the small test configuration is the design; its one deviation switched on images differently
    a = jsim.Session(small_config(), backend="cpu").simulate(0)
    b = jsim.Session(small_config(**{"as_built.wavefront_rms_nm": 30.0}), backend="cpu").simulate(0)
    assert not np.array_equal(a.image, b.image)


def test_a_bad_field_raises_value_error_naming_it(cfg):
    with pytest.raises(ValueError, match="ace.no_such_field"):
        cfg.set("ace.no_such_field", 1)
    with pytest.raises(ValueError, match="ace.sigma_mas"):
        cfg.set("ace.sigma_mas", "lots")
    cfg.set("detector.gain_e_per_adu", -1.0)  # ranges are checked once, after every change
    with pytest.raises(ValueError, match="detector.gain_e_per_adu"):
        cfg.validate()
    with pytest.raises(ValueError, match="detector.gain_e_per_adu"):
        jsim.Session(cfg)
    with pytest.raises(ValueError, match="fidelity.backend"):
        jsim.Session(small_config(), backend="quantum")
    with pytest.raises(OSError, match="no_such.toml"):
        jsim.Config.from_toml("no_such.toml")
    assert jsim.Config.from_toml("") == jsim.Config.default()
    with pytest.raises(ValueError, match="sigma_mas"):
        jsim.Config.from_toml("[ace]\nsigma_mas = 'x'\n")


def test_bad_arrays_and_arguments_raise_not_crash(session, exposure):
    with pytest.raises(TypeError, match="dtype"):
        session.analyze(exposure.image.astype(np.complex64))
    with pytest.raises(TypeError, match="dtype"):
        session.analyze(np.full((64, 64), "a"))
    with pytest.raises(TypeError, match="numpy array"):
        session.analyze([[1.0, 2.0], [3.0, 4.0]])
    with pytest.raises(ValueError, match="2-D"):
        session.analyze(np.zeros(100, dtype=np.float32))
    with pytest.raises(ValueError, match="2-D"):
        session.analyze(np.zeros((2, 64, 64), dtype=np.float32))
    with pytest.raises(ValueError, match="empty"):
        session.analyze(np.zeros((0, 64), dtype=np.float32))
    with pytest.raises(ValueError, match="dq"):
        session.analyze(exposure.image, exposure.header, dq=np.zeros((3, 3), dtype=np.uint8))
    with pytest.raises(TypeError, match="dq"):
        session.analyze(exposure.image, exposure.header, dq=np.zeros(exposure.image.shape))
    bad_truth = dict(exposure.truth)
    del bad_truth["flux_e"]
    with pytest.raises(ValueError, match="flux_e"):
        session.analyze(exposure.image, exposure.header, truth=bad_truth)
    with pytest.raises(ValueError, match="GAIN"):
        session.analyze(exposure.image, {**exposure.header, "GAIN": -2.0})
    with pytest.raises(ValueError, match="IMAGEIDX"):
        session.analyze(exposure.image, {"GAIN": 3.0}, config=exposure.config)
    with pytest.raises(TypeError, match="Exposure"):
        session.analyze(exposure, exposure.header)
    with pytest.raises(ValueError, match="plate-poly"):
        session.analyze(exposure, countermeasure="plate-poly:99")
    with pytest.raises(ValueError, match="image = 3"):
        session.simulate(image=3)
    with pytest.raises(RuntimeError, match="exact-epsf"):
        session.analyze(exposure, countermeasure="exact-epsf")  # realistic ACE: the control does not apply


def test_a_blank_image_is_an_error_not_a_crash(session):
    with pytest.raises(RuntimeError, match="no star"):
        session.analyze(np.zeros((128, 128), dtype=np.float32), {"GAIN": 3.0, "RDNOISE": 21.2})


def test_the_ace_and_the_prediction(session, exposure):
    ace = session.ace()
    assert len(ace["t_s"]) == len(ace["x_mas"]) > 1000
    dt = np.diff(ace["t_s"][:3])
    assert dt[0] > 0 and np.isclose(dt[0], dt[1])
    e = exposure.ace
    assert e["t_s"][0] <= exposure.header["TSTART"] <= e["t_s"][-1]
    # the per-exposure ACE std in the header is the std of this series over the exposure's window
    p = session.predict(["none", "plate-poly:3@oracle"])
    assert set(p) == {"none", "plate-poly:3@oracle"}
    assert p["plate-poly:3@oracle"] < p["none"]


def test_the_gil_is_released_while_the_engine_works():
    """With a long switch interval a thread that held the GIL would starve this one: the counter only
    moves between the progress callbacks if the engine lets go of the GIL."""
    counter = [0]
    seen = []
    stop = threading.Event()

    def count():
        while not stop.is_set():
            counter[0] += 1

    old = sys.getswitchinterval()
    sys.setswitchinterval(5.0)
    t = threading.Thread(target=count)
    t.start()
    try:
        jsim.experiment(
            small_config(),
            aces=["gaussian"],
            mags=[12.5],
            countermeasures="none",
            progress=lambda done, total: seen.append(counter[0]),
            as_frame=False,
        )
    finally:
        stop.set()
        t.join()
        sys.setswitchinterval(old)
    assert len(seen) == 3
    assert seen[-1] > seen[0] > 0, seen


def test_ctrl_c_stops_an_experiment_between_images():
    calls = []

    def progress(done, total):
        calls.append(done)
        if done == 1:
            _thread.interrupt_main()  # a Ctrl-C arriving while the engine works on image 2

    # Python's own Ctrl-C handler (a process started in the background, as under CI, inherits SIGINT
    # ignored, and then Python installs none and interrupt_main does nothing)
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            jsim.experiment(
                small_config(),
                aces=["gaussian"],
                mags=[12.5, 13.0],
                countermeasures="none",
                progress=progress,
                as_frame=False,
            )
    finally:
        signal.signal(signal.SIGINT, old)
    assert calls and calls[-1] < 6, calls


def test_a_progress_callback_error_stops_the_experiment():
    def progress(done, total):
        raise ValueError("stop here")

    with pytest.raises(ValueError, match="stop here"):
        jsim.experiment(small_config(), aces=["gaussian"], mags=[12.5], progress=progress)


def test_experiment_as_frame_only_with_pandas(cfg):
    rows = jsim.experiment(cfg, aces=["gaussian"], mags=[12.5], countermeasures="none", as_frame=False)
    assert isinstance(rows, dict)
    try:
        import pandas  # noqa: F401
    except ImportError:
        assert isinstance(
            jsim.experiment(cfg, aces=["gaussian"], mags=[12.5], countermeasures="none"), dict
        )
        with pytest.raises(ImportError):
            jsim.experiment(cfg, aces=["gaussian"], mags=[12.5], countermeasures="none", as_frame=True)


def test_help_states_the_units():
    assert "uint16" in jsim.Exposure.image.__doc__
    assert "fidelity.images" in jsim.Session.simulate.__doc__
    for unit in ["ADU", "pixels", "electrons", "mas"]:
        assert unit in jsim.Session.simulate.__doc__, unit
    assert "mas" in jsim.Session.predict.__doc__
    assert "_mas" in jsim.__doc__


def test_an_exposure_off_its_design_carries_the_truth_in_the_headers_frame():
    """With a pointing, roll and distortion the header does not know, Exposure.truth carries x_header, y_header
    (each star's true sky place through the header's design WCS), and jsim.score on them gives the accuracy the
    analysis referenced to the catalogue reports; on x, y the roll and distortion count as error."""
    cfg = small_config(**{
        "as_built.pointing_offset_arcsec": [2.0, -1.0],
        "as_built.roll_offset_arcsec": 120.0,
        "as_built.distortion_px": 0.03,
        "fidelity.images": 1,
        "ace.case": "gaussian",
    })
    s = jsim.Session(cfg, backend="cpu")
    e = s.simulate(0)
    assert {"x_header", "y_header"} <= set(e.truth)
    a = s.analyze(e, countermeasure="plate-affine@catalogue")
    measured = {"x": a.catalogue["x"], "y": a.catalogue["y"], "flags": a.catalogue["flags"]}
    scale = e.header["PLTSCALE"]

    def accuracy(xcol, ycol):
        t = {"x": e.truth[xcol], "y": e.truth[ycol], "mag": e.truth["mag_hw"]}
        return jsim.score(measured, t, plate_scale_mas=scale)["all"]["accuracy_mas"]

    header, image = accuracy("x_header", "y_header"), accuracy("x", "y")
    assert header == pytest.approx(a.summary["accuracy_mas"], rel=1e-9)
    assert image > 2.0 * header
    # without deviations the truth has no header frame (the frames agree)
    assert "x_header" not in s.__class__(small_config(), backend="cpu").simulate(0).truth
