"""Simulate one realistic-ACE frame, analyse it with and without a countermeasure, plot the vector maps.

    pip install matplotlib
    python engine/python/examples/vector_map.py            # writes vector_map.png

The telemetry correction is the countermeasure here: it needs only the exposure and the attitude telemetry
(the engine's default quality: 20 mas white per 1-kHz sample + 5 mas correlated over 1 s), so it works on a
single frame; the stack-referenced plate model needs a stare of several (jsim.experiment runs those).
"""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import jsim  # noqa: E402

cfg = jsim.Config.default()  # the paper's scene: 400 stars, Hw 12.5, realistic ACE, rolling readout
s = jsim.Session(cfg)
exp = s.simulate(image=1)
print(exp, "ACE σ over the exposure:", exp.header["ACESIGX"], exp.header["ACESIGY"], "mas")

fig, axes = plt.subplots(1, 2, figsize=(11, 5.5), sharey=True)
for ax, cm in zip(axes, ["none", "telemetry"]):
    rep = s.analyze(exp, countermeasure=cm)
    c, r = rep.catalogue, rep.summary
    used = c["truth_id"] >= 0
    # fitted − true about the frame's mean offset (the accuracy is the std about it)
    dx = c["dx_mas"][used] - c["dx_mas"][used].mean()
    dy = c["dy_mas"][used] - c["dy_mas"][used].mean()
    ax.quiver(c["x"][used], c["y"][used], dx, dy,
              angles="xy", scale_units="xy", scale=1 / 10)  # 1 mas = 10 px on the plot
    ax.set_title(f"{cm}: {r['accuracy_mas']:.2f} mas (bound {r['crlb_median_mas']:.2f})")
    ax.set_xlabel("x [px]")
    ax.set_aspect("equal")
    print(f"{cm:>10}: accuracy {r['accuracy_mas']:.2f} mas, bound {r['crlb_median_mas']:.2f} mas")
axes[0].set_ylabel("y [px]")
fig.suptitle("fitted − true positions, Hw 12.5, realistic ACE, rolling readout (mean offset removed; 1 mas = 10 px)")
fig.tight_layout()
fig.savefig("vector_map.png", dpi=90)
