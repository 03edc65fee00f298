"""Fill the gaps of real motion-capture markers, notebook style (run it cell by cell in
Jupyter or VS Code with the "# %%" markers, or as a script).

    python python/examples/fill_gaps.py [OUT_DIR] [--iters N]

Reads data/mocap/right_knee.c3d (73 markers, 100 Hz, in mm), takes every 4th frame of its
first 400, hides spans of 3 to 8 frames of observed entries so that the truth is known,
fits a motion field to what is left, fills every gap with ``Field.complete()``, and writes
OUT_DIR/fill_gaps.png: one hidden span of a marker, observed against filled. Errors are
Euclidean distances in the file's units (mm), beside linear interpolation's.
"""

# %% Imports and arguments
import argparse
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import doma  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("out", nargs="?", default="runs/fill_gaps", type=pathlib.Path)
parser.add_argument("--iters", type=int, default=None, help="default: doma's for tracks with gaps")
args, _ = parser.parse_known_args()
args.out.mkdir(parents=True, exist_ok=True)

# %% The markers: [T, N, 3] in mm, NaN where the cameras lost a marker
markers = doma.read_tracks(ROOT / "data" / "mocap" / "right_knee.c3d")
tracks, observed = markers.tracks[:400:4], markers.observed[:400:4]
print(f"{tracks.shape[1]} markers x {tracks.shape[0]} frames, {100 * (1 - observed.mean()):.1f}% not seen")

# %% Hide spans of seen entries, to measure the fill against the truth
rng = np.random.default_rng(0)
hidden = np.zeros_like(observed)
for i in rng.choice(tracks.shape[1], tracks.shape[1] // 2, replace=False):
    length = int(rng.integers(3, 9))
    start = int(rng.integers(1, tracks.shape[0] - length - 1))
    span = slice(start, start + length)
    if observed[span, i].all() and observed[start - 1, i] and observed[start + length, i]:
        hidden[span, i] = True
given = observed & ~hidden
print(f"hidden: {hidden.sum()} entries in {hidden.any(0).sum()} markers")

# %% Fit every marker, then fill every gap
options = {} if args.iters is None else {"iters": args.iters}
field = doma.fit(np.where(given[..., None], tracks, np.nan), given, drop_unobserved=True, **options)
filled = field.complete()
kept = filled.kept if filled.kept is not None else np.arange(tracks.shape[1])
print(f"{field.model}, reference frame {field.reference_frame}, {field.n_tracks} markers fitted")

# %% The error on the hidden entries, in mm, against linear interpolation
truth, mask = tracks[:, kept], hidden[:, kept]
fill_error = np.linalg.norm(filled.tracks[mask] - truth[mask], axis=-1).mean()
frames = np.arange(tracks.shape[0])
linear = truth.copy()
for i in range(truth.shape[1]):
    seen = given[:, kept[i]]
    for c in range(3):
        linear[:, i, c] = np.interp(frames, frames[seen], truth[seen, i, c])
linear_error = np.linalg.norm(linear[mask] - truth[mask], axis=-1).mean()
print(f"mean distance on the hidden entries: doma {fill_error:.2f} mm, linear {linear_error:.2f} mm")

# %% One hidden span, observed against filled
i = int(np.flatnonzero(mask.any(0))[0])
span = np.flatnonzero(mask[:, i])
window = slice(max(span[0] - 6, 0), min(span[-1] + 7, len(frames)))
fig, axes = plt.subplots(1, 3, figsize=(12, 3.5))
for c, ax in enumerate(axes):
    ax.plot(frames[window], truth[window, i, c], "k.", label="truth")
    ax.plot(frames[window], filled.tracks[window, i, c], "-", color="tab:blue", label="doma")
    ax.plot(frames[window], linear[window, i, c], "--", color="tab:gray", label="linear")
    ax.axvspan(span[0] - 0.5, span[-1] + 0.5, color="tab:orange", alpha=0.2, label="hidden")
    ax.set_xlabel("frame (25 Hz)")
    ax.set_ylabel(f"{'xyz'[c]} (mm)")
axes[0].legend(fontsize=8)
fig.suptitle(f"marker {kept[i]}: doma {fill_error:.2f} mm, linear {linear_error:.2f} mm (all hidden entries)")
fig.tight_layout()
path = args.out / "fill_gaps.png"
fig.savefig(path, dpi=100)
print(f"wrote {path}")
