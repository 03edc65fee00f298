"""doma: motion fields fitted to point trajectories (DOMA, CVPR 2024), from NumPy.

One small SIREN ``f(x, t)`` is fitted to observed 3-D tracks; it outputs a local
transformation ``(A, u)`` and moves any point ``x`` of the reference frame to
``y = A x + u`` (Eq. 4 of the paper). This package calls the Rust library in process: a
fit from Python is the fit of ``doma fit`` on the same data, with the same run folder,
and the command line can ``eval``, ``warp``, ``export`` and ``view`` it.

>>> import numpy as np, doma
>>> t = np.linspace(0, 1, 10)[:, None, None]
>>> x = np.random.default_rng(0).normal(size=(1, 300, 3))
>>> tracks = x + t * [0.5, 0.0, 0.0]                   # [T, N, 3], a translation
>>> field = doma.fit(tracks, iters=20, progress=False)
>>> field.warp(x[0], 9).shape                         # every point at frame 9
(300, 3)

Arrays: any float array is accepted; a C-contiguous ``float32`` one is read in place,
anything else (``float64``, Fortran order, a strided view) is converted once. Results
are new ``float32`` arrays. The GIL is released while Rust works; Ctrl-C stops a fit at
the end of its iteration with its checkpoint saved.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import warnings
from dataclasses import dataclass
from typing import Any, Callable, NamedTuple, Optional, Sequence, Union

import numpy as np

from . import _native

__version__: str = _native.__version__
__all__ = [
    "BACKENDS",
    "FILLERS",
    "Field",
    "FitProgress",
    "JACOBIANS",
    "OPTIMIZERS",
    "RECIPES",
    "STEPS",
    "SizeError",
    "Tracks",
    "VARIANTS",
    "fill",
    "fill_file",
    "fit",
    "load",
    "read_tracks",
    "resume",
]

PathLike = Union[str, "os.PathLike[str]"]
Frames = Union[float, Sequence[float], np.ndarray]

#: The choices of ``fit``'s and ``load``'s string arguments, from the library itself.
_CHOICES: dict[str, tuple[str, ...]] = {k: tuple(v) for k, v in _native.CHOICES.items()}
#: The models ``fit`` accepts: the DOMA variants (Eq. 4, 10–12) and the DPF baseline.
VARIANTS = _CHOICES["variant"]
#: The compute backends.
BACKENDS = _CHOICES["backend"]
#: How the spatial Jacobian inside L_H is computed.
JACOBIANS = _CHOICES["jacobian"]
#: The named recipes of ``fit(recipe=...)``.
RECIPES = _CHOICES["recipe"]
#: How ``fit(step=...)`` computes a training step.
STEPS = _CHOICES["step"]
#: The optimisers ``fit(optimizer=...)`` takes.
OPTIMIZERS = _CHOICES["optimizer"]
#: The methods of :func:`fill`: the gap fillers that need no field.
FILLERS = _CHOICES["filler"]


def _checked_array(value: Any, name: str, shape: Sequence[Optional[int]]) -> np.ndarray:
    """``value`` as an array of ``shape`` (None: any length) and a float dtype, not copied."""
    array = np.asarray(value)
    if array.dtype.kind != "f":
        raise ValueError(f"{name} must be a float array (float16, float32 or float64), not {array.dtype}")
    if array.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, array.shape)):
        want = ", ".join("any" if s is None else str(s) for s in shape)
        raise ValueError(f"{name} has shape {list(array.shape)}, not [{want}]")
    return array


def _float_array(value: Any, name: str, shape: Sequence[Optional[int]]) -> np.ndarray:
    """``value`` as a C-contiguous float32 array of ``shape`` (None: any length)."""
    return np.ascontiguousarray(_checked_array(value, name, shape), dtype=np.float32)


def _memory_bytes() -> Optional[int]:
    """This machine's physical memory, where the system says."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


class SizeError(ValueError, MemoryError):
    """A call whose arrays would not fit in this machine's memory, refused before anything
    is allocated. Both a ``ValueError`` (the arguments' shapes ask for it) and a
    ``MemoryError`` (what it guards against)."""


def _check_size(what: str, count: int, frames: int, per_point: int) -> None:
    """Refuses, before anything is allocated, a call whose float32 input and output
    (``count`` points, ``per_point`` outputs each at ``frames`` frames) and frame times
    exceed the machine's memory: a stride-0 view of 10⁹ points or frame times costs
    nothing until it is copied."""
    # Each frame time is held as a Python float in a list (32 bytes) and twice as an f64
    # on the Rust side.
    need = 4 * count * (3 + frames * per_point) + 48 * frames
    have = _memory_bytes()
    if have is not None and need > have:
        raise SizeError(
            f"{what} of {count} points at {frames} frame(s) needs {need / 2**30:.1f} GiB of "
            f"float32 input and output and frame times, more than this machine's "
            f"{have / 2**30:.1f} GiB: call it on chunks of the points or of the frames"
        )


#: The string arguments that name a choice: read in any case, as ``reg`` is.
_CHOICE_ARGUMENTS = (
    "variant", "backend", "jacobian", "recipe", "step", "optimizer", "robust", "h_weight", "layout",
    "frame",
)


def _lower_choices(options: dict[str, Any]) -> dict[str, Any]:
    """``options`` with every choice given as a string in lower case."""
    return {k: v.lower() if k in _CHOICE_ARGUMENTS and isinstance(v, str) else v for k, v in options.items()}


def _frames(t: Frames) -> tuple[np.ndarray, bool]:
    """The frame times of ``t`` (a number, or a 1-D array of them), flat and not copied,
    and whether it was one number. Sized with :func:`_check_size` before :func:`_times`
    turns them into a list."""
    array = np.asarray(t)
    if array.dtype.kind not in "iuf":
        raise ValueError(f"t must be a frame index or an array of them, not {array.dtype}")
    if array.ndim > 1:
        raise ValueError(f"t has shape {list(array.shape)}; give a frame index or a 1-D array of them")
    return array.reshape(-1), array.ndim == 0


def _times(frames: np.ndarray) -> list[float]:
    """The frame times as the list the native calls take."""
    return [float(v) for v in frames]


class FitProgress(NamedTuple):
    """What a ``progress`` callable of :func:`fit` and :func:`resume` is given after each
    iteration."""

    #: Iterations done (1 after the first).
    iteration: int
    #: Iterations of the schedule.
    iterations: int
    #: The trajectory loss (mean L1, Eq. 5, normalised units) averaged over the iteration.
    loss: float
    #: The EPE × 1e4 on the held-back training tracks, where the fit measured it
    #: (``until_converged``); else None.
    epe: Optional[float]
    #: Seconds since the fit started.
    seconds: float


Progress = Union[bool, Callable[[FitProgress], Any]]


def _progress(progress: Progress) -> tuple[bool, Optional[Callable[..., Any]]]:
    """``(bar, each)`` for the native fit: a callable is called with a
    :class:`FitProgress`; ``True`` draws the bar on a terminal, and elsewhere (a notebook,
    a log, a pipe) prints a plain line every tenth of the fit to ``sys.stderr``."""
    if callable(progress):
        user = progress
        return False, lambda *a: user(FitProgress(*a))
    if not progress:
        return False, None
    stream = sys.stderr
    if stream is not None and hasattr(stream, "isatty") and stream.isatty():
        return True, None

    def line(*a: Any) -> None:
        p = FitProgress(*a)
        if p.iteration % max(1, -(-p.iterations // 10)) == 0 or p.iteration == p.iterations:
            print(
                f"doma: iteration {p.iteration}/{p.iterations}  loss {p.loss:.2e}  {p.seconds:.1f} s",
                file=sys.stderr,
                flush=True,
            )

    return False, line


def _time_major(positions: np.ndarray, time_axis: Optional[int]) -> np.ndarray:
    """``positions`` as [T, N, 3]: transposed for ``time_axis=1``; with None, refused
    when the array looks like [N, T, 3] (neighbouring entries much closer along axis 1
    than along axis 0, as a track's successive frames are)."""
    if time_axis == 1:
        return positions.transpose(1, 0, 2)
    if time_axis not in (None, 0):
        raise ValueError(f"time_axis must be 0 ([T, N, 3]) or 1 ([N, T, 3]), not {time_axis!r}")
    if time_axis == 0 or positions.shape[0] < 3 or positions.shape[1] < 3:
        return positions

    def step(axis: int) -> float:
        d = np.abs(np.diff(positions, axis=axis)).sum(-1)
        d = d[np.isfinite(d)]
        return float(np.median(d)) if d.size else float("nan")

    along_0, along_1 = step(0), step(1)
    if along_1 < 0.3 * along_0:
        raise ValueError(
            f"tracks of shape {list(positions.shape)} look like [N, T, 3]: neighbouring "
            f"entries are {along_0 / max(along_1, 1e-30):.1f}x closer along axis 1 than along "
            "axis 0, as a track's successive frames are. Pass time_axis=1 to read them as "
            "[N, T, 3], or time_axis=0 to fit them as [T, N, 3]"
        )
    return positions


class Field:
    """A fitted motion field and its run folder (from :func:`fit`, :func:`load` or :func:`resume`).

    Points are in the data's own units and frame; ``t`` is a frame index of the fitted
    clip (``0 … frames - 1``; fractional values lie between frames), or a 1-D array of them.
    """

    def __init__(self, native: _native.Field) -> None:
        self._native = native
        self._canonical: Optional[np.ndarray] = None

    def warp(self, points: Any, t: Frames, *, from_frame: Optional[float] = None) -> np.ndarray:
        """Moves ``points`` ([M, 3]) given at the reference frame (:attr:`reference_frame`)
        to frame ``t``: ``y = A x + u`` (Eq. 4).

        ``from_frame``: the frame the points are given at, when not the reference frame;
        they are first brought back to it (:meth:`to_reference`).

        Returns [M, 3], or [K, M, 3] for K frames. Memory holds the input, the output and
        one chunk of 16,384 points' activations, however large M is.
        """
        if from_frame is not None:
            points = self.to_reference(points, from_frame)
        frames, one = _frames(t)
        _check_size("warp", _checked_array(points, "points", (None, 3)).shape[0], frames.size, 3)
        x = _float_array(points, "points", (None, 3))
        out = np.empty((frames.size, x.shape[0], 3), dtype=np.float32)
        self._native.warp_into(x, _times(frames), out)
        return out[0] if one else out

    def to_reference(
        self, points: Any, frame: float, *, tolerance: float = 1e-4, max_steps: int = 50
    ) -> np.ndarray:
        """The points ``x`` of the reference frame that the field moves to ``points``
        ([M, 3], given at ``frame``): the inverse of the warp, ``warp(x, frame) = points``.

        Each point starts from its nearest track (of :attr:`canonical` moved to ``frame``),
        shifted by its offset from it there, and is refined by damped Newton steps with the
        field's own Jacobian (Eq. 6): a step that does not bring the point closer is halved,
        up to 8 times. Stops when every point is within ``tolerance`` × the data's scale
        (:attr:`normalisation`) of its target (the default is above the float32 field's
        own rounding, about 10⁻⁶ of the scale); a point still farther after ``max_steps``
        steps (where the motion folds space) raises ``ValueError`` naming it. Returns
        [M, 3] float32.
        """
        frames, one = _frames(frame)
        if not one:
            raise ValueError(f"frame must be one frame index, not an array of shape {list(np.shape(frame))}")
        # The Newton loop holds about 40 numbers a point (the target and the iterate in
        # float64, residuals, errors, a warp and a Jacobian of the pending points).
        _check_size("to_reference", _checked_array(points, "points", (None, 3)).shape[0], 1, 40)
        target = _float_array(points, "points", (None, 3))
        frame = frames[0].item()
        if frame == self.reference_frame:
            return target.copy()
        goal = target.astype(np.float64)
        _, scale = self.normalisation
        canonical = self.canonical.astype(np.float64)
        moved = self.warp(canonical, frame).astype(np.float64)
        x = np.empty_like(goal)
        rows = max(1, 4_000_000 // max(1, len(moved)))
        for a in range(0, len(goal), rows):
            near = ((goal[a : a + rows, None, :] - moved[None]) ** 2).sum(-1).argmin(1)
            x[a : a + rows] = canonical[near] + goal[a : a + rows] - moved[near]

        def miss(at: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            r = self.warp(at, frame).astype(np.float64) - goal[rows]
            return r, np.linalg.norm(r, axis=1)

        everyone = np.arange(len(goal))
        residual, error = miss(x, everyone)
        for _ in range(max_steps):
            pending = np.flatnonzero(error > tolerance * scale)
            if pending.size == 0:
                break
            j = self.jacobian(x[pending], frame).astype(np.float64)
            step = (np.linalg.pinv(j) @ residual[pending][..., None])[..., 0]
            length = 1.0
            for _ in range(8):
                trial = x[pending] - length * step
                r, e = miss(trial, pending)
                better = e < error[pending]
                kept = pending[better]
                x[kept], residual[kept], error[kept] = trial[better], r[better], e[better]
                pending, step = pending[~better], step[~better]
                if pending.size == 0:
                    break
                length /= 2
        far = np.flatnonzero(error > tolerance * scale)
        if far.size:
            raise ValueError(
                f"to_reference: {far.size} of {len(goal)} points (the first is point {far[0]}) "
                f"have no point of the reference frame that the field moves to them at frame "
                f"{frame} within {tolerance} x the scale, after {max_steps} Newton steps"
            )
        return x.astype(np.float32)

    def jacobian(self, points: Any, t: Frames) -> np.ndarray:
        """The Jacobian ``∂y/∂x`` of the warp at ``points`` ([M, 3]) and frame ``t``.

        Returns [M, 3, 3] (or [K, M, 3, 3]) with ``J[m, i, j] = ∂y_i/∂x_j``: the local
        deformation gradient, ``A`` plus the terms of A's and u's variation (Eq. 6).
        """
        frames, one = _frames(t)
        _check_size("jacobian", _checked_array(points, "points", (None, 3)).shape[0], frames.size, 9)
        x = _float_array(points, "points", (None, 3))
        out = np.empty((frames.size, x.shape[0], 3, 3), dtype=np.float32)
        self._native.jacobian_into(x, _times(frames), out)
        return out[0] if one else out

    def complete(
        self,
        *,
        max_gap: Union[None, int, str] = None,
        extrapolate: Optional[bool] = None,
        method: Optional[str] = None,
    ) -> "Tracks":
        """Every track at every frame of the fitted clip, gaps filled: what ``doma complete``
        writes, to the last bit (with ``--max-gap`` and ``--extrapolate`` as given here).

        By default every gap with observations on both sides is filled; before a track's
        first observation and after its last, a tracker's output (a PointOdyssey or
        TAPVid-3D file) is filled and a recording (.c3d, .trc) or other tracks are not
        (``extrapolate=True`` or ``False`` says which).
        ``max_gap``: fill only gaps of at most that many frames of the input (an int), or
        seconds at a C3D input's rate (``"0.5s"``). An entry left unfilled is NaN.
        ``method``: fill with one filler alone instead of doma's blend: ``"field_fill"``
        (the field's fill), ``"field_fill_framewise"``, or one of :data:`FILLERS`.

        Returns a :class:`Tracks` in the input's units, frame and track order: ``tracks``
        [T, N, 3] float32 (an observed entry as the input holds it, every other filled by
        doma's fill: the field corrected by its nearest tracks' residuals at that frame
        and by the track's own residual carried across the gap, blended with the classic
        fillers (:data:`FILLERS`) by weights learned
        on this data's own observations, as ``doma complete`` prints them), ``observed`` the
        input's mask, ``kept`` the input's index of each track when the fit dropped
        tracks never observed (else None), and ``blend`` the weights the fill used per
        class of gap with each class's held-out figures (as ``doma complete --blend``
        writes them).
        """
        if max_gap is not None and not isinstance(max_gap, (int, str)):
            raise ValueError(f"max_gap must be frames (an int) or seconds ('0.5s'), not {max_gap!r}")
        gap = None if max_gap is None else str(max_gap)
        if method is not None and not isinstance(method, str):
            raise ValueError(f"method must be a filler's name, not {method!r}")
        ends = None if extrapolate is None else bool(extrapolate)
        positions, (t, n), observed, kept, blend = self._native.complete(gap, ends, method)
        return Tracks(
            tracks=np.frombuffer(positions, dtype=np.float32).reshape(t, n, 3),
            observed=np.frombuffer(observed, dtype=np.bool_).reshape(t, n),
            faces=None,
            weights=None,
            kept=None if kept is None else np.asarray(kept, dtype=np.int64),
            blend=json.loads(blend),
        )

    @property
    def canonical(self) -> np.ndarray:
        """[N, 3] float32, in the data's units: each fitted track's point at the
        reference frame, the ``points`` that :meth:`warp` moves along it (where the
        track is not seen there, placed by the fit)."""
        # Read from the run's data once: to_reference asks for it on every call.
        if self._canonical is None:
            self._canonical = np.frombuffer(self._native.canonical, dtype=np.float32).reshape(-1, 3)
        return self._canonical.copy()

    @property
    def reference_frame(self) -> int:
        """The frame of the clip whose positions ``warp`` takes as ``points``: the one with
        the most observed tracks, unless the fit named one (``reference_frame=``). Points
        given at another frame must first be brought to it."""
        return self._native.reference_frame

    def evaluate(self, data: Union[None, PathLike, "Tracks"] = None) -> dict:
        """The metrics of ``doma eval``: on the run's held-out points, or on every
        observed entry of ``data`` (a file of the same tracks and frames, or a
        :class:`Tracks`, e.g. the truth of entries a tracker missed).

        ``epe_x1e4`` is the mean L1 end-point error × 10⁴ in the run's normalised units
        (see :attr:`report`)."""
        if isinstance(data, Tracks):
            positions = _float_array(data.tracks, "data.tracks", (None, None, 3))
            observed = np.asarray(data.observed, dtype=np.bool_)
            if observed.shape != positions.shape[:2]:
                raise ValueError(
                    f"data.observed has shape {list(observed.shape)}, but data.tracks of shape "
                    f"{list(positions.shape)} need {list(positions.shape[:2])}"
                )
            with tempfile.TemporaryDirectory(prefix="doma-eval-") as d:
                path = os.path.join(d, "tracks.npz")
                np.savez(path, tracks=np.where(observed[..., None], positions, 0), observed=observed)
                return json.loads(self._native.evaluate(path, True))
        return json.loads(self._native.evaluate(None if data is None else os.fspath(data)))

    def save(self, run_dir: PathLike) -> None:
        """Copies the run into the new folder ``run_dir``, which the CLI and :func:`load` open."""
        self._native.save(os.fspath(run_dir))

    @property
    def run_dir(self) -> Optional[str]:
        """The run folder, or None for the temporary one of a fit without ``out``."""
        d = self._native.run_dir
        return None if d is None else os.fspath(d)

    @property
    def n_frames(self) -> int:
        """The number of frames of the fitted clip."""
        return self._native.frames

    @property
    def n_tracks(self) -> int:
        """The number of tracks of the fitted data (training and held-out)."""
        return self._native.tracks

    @property
    def frames(self) -> int:
        """Deprecated: :attr:`n_frames` (a count, where :attr:`Tracks.tracks` is an array)."""
        warnings.warn("Field.frames is Field.n_frames", DeprecationWarning, stacklevel=2)
        return self.n_frames

    @property
    def tracks(self) -> int:
        """Deprecated: :attr:`n_tracks` (a count, where :attr:`Tracks.tracks` is an array)."""
        warnings.warn("Field.tracks is Field.n_tracks", DeprecationWarning, stacklevel=2)
        return self.n_tracks

    @property
    def model(self) -> str:
        """The model's name in the paper's tables: ``Affinity``, ``SE(3)``, ``DPF``, ..."""
        return self._native.model

    @property
    def backend(self) -> str:
        """The backend it runs on: ``flex``, ``ndarray`` or ``wgpu``."""
        return self._native.backend

    @property
    def config(self) -> dict:
        """The run's ``config.json``."""
        return json.loads(self._native.config)

    @property
    def report(self) -> Optional[dict]:
        """The run's ``report.json``, None before the fit ends.

        ``epe_x1e4`` is the mean L1 end-point error × 10⁴ on the held-out tracks (or the
        fitted ones', when none is held out; ``evaluated_on`` says which), in normalised
        units: the canonical positions' bounding box, its longest side spanning 2 (see
        :attr:`normalisation`). ``held_out_observations.distance`` is the gap fill's mean
        Euclidean error in the data's own units."""
        text = self._native.report
        return None if text is None else json.loads(text)

    @property
    def normalisation(self) -> tuple[np.ndarray, float]:
        """``(center, scale)``: the field works on ``(x - center) / scale``."""
        center, scale = self._native.normalisation
        return np.asarray(center, dtype=np.float32), float(scale)

    def __repr__(self) -> str:
        where = self.run_dir or "a temporary folder"
        return f"<doma.Field {self.model} on {self.backend}, {self.n_tracks} tracks × {self.n_frames} frames, in {where}>"


def _mask(observed: Any, positions: np.ndarray, time_axis: Optional[int]) -> np.ndarray:
    """``observed`` as the C-contiguous uint8 view of a bool array of the tracks' [T, N]."""
    mask_array = np.asarray(observed)
    if time_axis == 1 and mask_array.ndim == 2:
        mask_array = mask_array.T
    if mask_array.dtype != np.bool_:
        raise ValueError(f"observed must be a bool array, not {mask_array.dtype}")
    if mask_array.shape != positions.shape[:2]:
        raise ValueError(
            f"observed has shape {list(mask_array.shape)}, but tracks of shape "
            f"{list(positions.shape)} need {list(positions.shape[:2])}"
        )
    return np.ascontiguousarray(mask_array).view(np.uint8)


def _gap_spans(observed: np.ndarray) -> list[tuple[int, int, int, bool]]:
    """Each gap of each track of ``observed`` ([T, N] bool): (track, first, end, interior),
    ``end`` excluded; interior where the track is observed on both sides."""
    spans = []
    t = observed.shape[0]
    for i in range(observed.shape[1]):
        seen = observed[:, i]
        if not seen.any():
            continue
        edges = np.flatnonzero(np.diff(np.concatenate(([1], seen.astype(np.int8), [1]))))
        for a, b in zip(edges[::2], edges[1::2]):
            spans.append((i, int(a), int(b), a > 0 and b < t))
    return spans


def _max_gap_frames(max_gap: Union[None, int, str], rate: Optional[float]) -> Optional[int]:
    """``max_gap`` in frames: an int, ``"N"`` frames, or ``"Xs"`` seconds at ``rate``."""
    if max_gap is None:
        return None
    if isinstance(max_gap, (int, np.integer)) and not isinstance(max_gap, bool) and max_gap >= 0:
        return int(max_gap)
    text = str(max_gap).strip()
    try:
        if text.endswith("s"):
            seconds = float(text[:-1])
            if rate is None:
                raise ValueError(
                    f"max_gap={max_gap!r} is in seconds, and the tracks have no rate: pass "
                    "rate=, or Tracks read from a .c3d or .trc"
                )
            if seconds >= 0 and np.isfinite(seconds):
                return int(np.floor(seconds * rate))
        elif int(text) >= 0:
            return int(text)
    except ValueError as e:
        if "rate" in str(e):
            raise
    raise ValueError(f"max_gap={max_gap!r} is not a gap length: N frames, or 'Xs' seconds (e.g. '0.5s')")


def fill(
    tracks: Any,
    observed: Any = None,
    method: str = "chain",
    *,
    max_gap: Union[None, int, str] = None,
    extrapolate: bool = False,
    rate: Optional[float] = None,
    time_axis: Optional[int] = None,
) -> np.ndarray:
    """Fills the gaps of ``tracks`` ([T, N, 3]) that ``observed`` ([T, N] bool) leaves by
    one of the classic fillers, without a fit, with ``doma fill``'s defaults: the
    gaps with observations on both sides, of any length unless ``max_gap`` (frames, or
    ``"0.5s"`` at ``rate`` frames per second), and nothing before a track's first
    observation or after its last unless ``extrapolate``. ``tracks`` may be the
    :class:`Tracks` that :func:`read_tracks` returns (its mask and rate are used). It is one
    filler: ``doma fill`` (and :func:`fill_file`) also fill a marker on a moving rigid
    cluster from its mates first.

    Methods (:data:`FILLERS`, each described in docs/usage.md, "The fillers"): ``chain``
    (the default, doma's: the rigid-body fill with its donors passed on where they are
    lost), ``rigid_body`` and ``pattern`` (Vicon Nexus's), ``kalman`` (Burke & Lasenby's
    smoother, as pyCGM2 runs it), ``gloersen`` (Gløersen & Federolf's PCA fill), and the
    others. The command line's kebab-case spellings (``rigid-body``) are accepted too.
    Where a gap is not interior or has too few donors, ``rigid_body``, ``segment`` and
    ``pattern`` give the linear fill (``chain`` where it is not interior); where no two
    frames see every marker, so does ``kalman``; where every marker has a gap, so does
    ``gloersen``.

    Returns a new [T, N, 3] float32 array: the observed entries as given, the gaps asked
    for filled, every other unobserved entry NaN.
    """
    if isinstance(tracks, Tracks):
        if observed is None:
            observed = tracks.observed
        rate = tracks.rate if rate is None else rate
        tracks = tracks.tracks
    if observed is None:
        raise ValueError("observed: give the [T, N] mask (or Tracks from read_tracks)")
    positions = _time_major(_checked_array(tracks, "tracks", (None, None, 3)), time_axis)
    positions = np.ascontiguousarray(positions, dtype=np.float32)
    mask = _mask(observed, positions, time_axis)
    name = method.lower().replace("-", "_") if isinstance(method, str) else None
    if name not in FILLERS:
        raise ValueError(f"method {method!r} is not one of {', '.join(FILLERS)}")
    longest = _max_gap_frames(max_gap, rate)
    out = np.empty_like(positions)
    _native.fill_into(positions, mask, name, out)
    seen = mask.view(np.bool_)
    for i, a, b, interior in _gap_spans(seen):
        if (not interior and not extrapolate) or (interior and longest is not None and b - a > longest):
            out[a:b, i] = np.nan
    never = ~seen.any(axis=0)
    out[:, never] = np.nan
    return out


def fill_file(
    path: PathLike,
    out: PathLike,
    *,
    fit: bool = False,
    max_gap: Union[None, int, str] = None,
    extrapolate: Optional[bool] = None,
    method: Optional[str] = None,
    overwrite: bool = False,
    flag_above_mm: float = 5.0,
) -> dict:
    """Fills the gaps of the recording at ``path`` (.c3d, .trc, or any format
    :func:`read_tracks` reads) into ``out``, as ``doma fill`` does: without a fit, rigid
    clusters first and then the chain fill (or ``method`` alone); ``fit=True`` fits a field
    and fills with doma's fill, the validated blend (``doma fill --fit``). Written in the format of
    ``out``'s extension (a ``.c3d`` is the C3D input with only its gaps written; ``.trc``;
    ``.npz``), and the table of filled gaps written beside it (``NAME.gaps.csv``).

    ``max_gap`` (frames, or ``"0.5s"``) as :func:`fill`'s; ``extrapolate`` as
    :meth:`Field.complete`'s (by default a tracker's file is filled past the tracks' ends,
    a recording is not). An existing
    ``out`` is refused (``FileExistsError``) unless ``overwrite``.

    Returns the report: ``markers``, ``frames``, ``filled``, ``extrapolated``,
    ``unfilled`` (entries), ``left_long`` (gaps longer than ``max_gap`` left),
    ``filled_by``, ``gaps`` (per filled gap: ``marker``, ``first_frame``, ``last_frame``,
    ``start_s``, ``end_s``, ``length_frames``, ``length_s``, ``past_ends``, ``filled_by``,
    ``expected_error`` in ``units`` and ``flagged`` where it passes ``flag_above_mm``;
    the flagged first), ``units``, ``calibration`` (the factor from the donor fillers'
    spread to the expected error, and the hidden spans that chose it) and ``csv`` (the
    table's path).
    """
    text = _native.fill_file(
        os.fspath(path),
        os.fspath(out),
        bool(fit),
        None if max_gap is None else str(max_gap),
        None if extrapolate is None else bool(extrapolate),
        None if method is None else str(method).lower(),
        bool(overwrite),
        float(flag_above_mm),
    )
    return json.loads(text)


def fit(
    tracks: Any,
    observed: Any = None,
    *,
    reg: Optional[str] = None,
    progress: Progress = True,
    out: Optional[PathLike] = None,
    overwrite: bool = False,
    time_axis: Optional[int] = None,
    **options: Any,
) -> Field:
    """Fits a motion field to ``tracks``, as ``doma fit`` does.

    The options are ``doma fit``'s flags by the same names (``--iters`` is ``iters``,
    ``--test-fraction`` is ``test_fraction``), read by the library into the one options
    type that the command line and batch manifests use; None leaves the library's default.

    Args:
        tracks: [T, N, 3] positions (any float dtype; a NumPy array, or anything with
            ``__array__``, such as a CPU PyTorch tensor). Entries that ``observed`` marks
            False are never read (NaN is fine there).
        time_axis: 0 for [T, N, 3], 1 for [N, T, 3] (a common tracker layout). Without
            it, an array that looks like [N, T, 3] (its entries much closer along axis 1
            than along axis 0) is refused rather than fitted the wrong way round.
        observed: optional [T, N] bool mask of the entries a tracker saw.
        variant: one of ``VARIANTS``: ``trans``, ``se3``, ``scaled-se3``, ``affinity`` (the
            DOMA variants; default) or ``dpf``.
        reg: None, or ``"h"`` for the smoothness loss L_H (Eq. 13) with ``h_weight``
            (default 0.1).
        **options: the fit's options, below.
        h_weight: L_H's weight (0: off), or ``"auto"`` to choose it by validation on
            held-out training points; a weight alone turns L_H on.
        iters: iterations (passes over all frames; default 1000, the paper's, or 300 for
            tracks with gaps).
        learning_rate: Adam's base learning rate (default 1e-4, the authors'; it wins over
            a recipe's).
        init_scale: the initialisation's weight scale: every SIREN weight but the output
            layer's drawn this many times wider (default 1, the authors').
        time_scale: the factor s on the time the field reads, f(x, s·t) (default 1 up to
            1,000 frames, else the frames over 1,000: a long recording's field keeps the
            frequencies per frame of a short clip).
        t_weight: the weight of the temporal smoothness loss L_T, the squared acceleration
            of the fitted tracks' paths (default 0: off).
        recipe: ``"paper"`` (the paper's protocol, the default), ``"fast"`` (1.5 times
            the learning rate with a warm-up and a cosine decay, 256 training points and 64
            L_H samples per step) or ``"soap"`` (``"fast"`` over 400 iterations at 3 times
            the rate, stepped by SOAP; the fused step only); the other options override it.
        until_converged: stop once the EPE on a held-back tenth of the training tracks has
            not improved for this many iterations, after as many iterations of a learning
            rate falling to 0 (those tracks are then not fitted).
        backend: one of ``BACKENDS`` (default ``flex``).
        jacobian: ``analytic`` (fused, hand-derived; default) or ``autodiff``.
        step: ``"auto"`` (default: the whole training step as one CPU operation where
            it applies, Burn's operations elsewhere), ``"fused"`` (refused where it does
            not apply) or ``"composed"`` (Burn's operations).
        optimizer: ``"adam"`` (default, the paper's) or ``"soap"`` (Adam in the eigenbasis
            of Shampoo's factors of each weight matrix; the fused step only).
        seed: seed of the weights, the split and the frame order (default 0).
        test_fraction: the fraction of tracks held out of the fit for the report
            (default 0: every track is fitted; the paper's Tab. 1 holds out 0.75).
        points_per_step, frames_per_step: a random subset of K training points per step;
            B frames per Adam step (defaults: all points, one frame: the paper's protocol).
        frames_per_iteration: a random subset of F frames per iteration, so that a fit
            costs ``iters * F`` steps whatever the recording's length (default: every
            frame; tracks with gaps: 100).
        reference_frame: the frame whose positions are the input ``x`` (default: the most
            observed one).
        drop_unobserved: go on without tracks never observed rather than refuse them.
        holdout_observations: hide this fraction of the observations, in spans, and
            report the EPE on them (``report["held_out_observations"]``).
        blind_validation: on tracks with gaps, hide a tenth of the gapped tracks'
            observations from the fit and weigh the field's fills in :meth:`Field.complete`'s
            blend on them, where the field has not seen the answer (default True; False fits
            every observation, and the blend holds the classic fillers alone).
        fits: fit K fields, with ``seed`` and the K - 1 seeds after it, and fill each gap
            in :meth:`Field.complete` with the median of their fills (the mean of two),
            at K times the cost (default 1; the others fitted into ``out/fits/2``, ...).
        robust: ``"huber[:delta]"`` or ``"charbonnier[:eps]"``, a robust trajectory loss.
        checkpoint_every: iterations between checkpoints (default 50).
        progress: True: a bar on a terminal, else (a notebook, a log) a line every tenth
            of the fit on ``sys.stderr``; False: nothing; or a callable, called after every
            iteration with a :class:`FitProgress` (an exception it raises stops the fit
            as Ctrl-C does, with the checkpoint saved, and is raised).
        out: the run folder to write (it must not hold a run); default a temporary one,
            removed with the field (:meth:`Field.save` keeps it). The folder is locked
            before anything in it is touched: a second fit into it is refused, and a
            refused fit leaves every file there as it was.
        overwrite: replace files of an earlier fit's kind (``tracks.npz``, ``model.bpk``,
            ``report.json``, ...) that ``out`` holds outside a run; without it they are
            refused (FileExistsError).

    Raises:
        ValueError: bad shapes, dtypes, values or options. TypeError: an option of the
        wrong type. FileExistsError: ``out`` holds a run, or a file a fit writes.
        OSError: another fit holds ``out``. KeyboardInterrupt: Ctrl-C; the
        checkpoint is saved (see :func:`resume`).
    """
    positions = _time_major(_checked_array(tracks, "tracks", (None, None, 3)), time_axis)
    positions = np.ascontiguousarray(positions, dtype=np.float32)
    mask = None if observed is None else _mask(observed, positions, time_axis)
    if isinstance(reg, str):
        reg = reg.lower()
    if reg not in (None, "h"):
        raise ValueError(f"reg {reg!r} is not None or 'h' (the smoothness loss L_H)")
    if reg == "h" and options.get("h_weight") is None:
        options["h_weight"] = 0.1
    options = _lower_choices(options)
    bar, each = _progress(progress)
    native = _native.fit(
        positions,
        mask,
        out=None if out is None else os.fspath(out),
        progress=bar,
        each=each,
        overwrite=bool(overwrite),
        **options,
    )
    return Field(native)


def resume(run_dir: PathLike, *, progress: Progress = True) -> Field:
    """Continues the interrupted fit in ``run_dir`` (from Python or ``doma fit``) to its
    end; ``progress`` as in :func:`fit`."""
    bar, each = _progress(progress)
    return Field(_native.resume(os.fspath(run_dir), bar, each))


def load(run_dir: PathLike, *, backend: Optional[str] = None) -> Field:
    """Opens a fitted run folder (``doma fit``'s, or ``fit(out=...)``'s) on its backend or ``backend``."""
    return Field(_native.load(os.fspath(run_dir), backend.lower() if isinstance(backend, str) else backend))


@dataclass(frozen=True)
class Tracks:
    """A sequence file read as ``doma fit`` reads it, or a completion (:meth:`Field.complete`)."""

    #: [T, N, 3] float32 positions; NaN where not observed.
    tracks: np.ndarray
    #: [T, N] bool: the entries the file observes (all True for complete formats).
    observed: np.ndarray
    #: [F, 3] uint32 triangle indices, where the format has faces; else None.
    faces: Optional[np.ndarray]
    #: [T, N] float32 confidence weights with ``confidence=KEY``; else None.
    weights: Optional[np.ndarray]
    #: [N] int64: the input's index of each track: from :meth:`Field.complete` when the
    #: fit dropped tracks never observed, from :func:`read_tracks` when it left out a C3D
    #: file's model outputs; else None.
    kept: Optional[np.ndarray] = None
    #: The marker names, one per track, of a .c3d or .trc file; else None.
    labels: Optional[tuple[str, ...]] = None
    #: Frames per second of a .c3d or .trc file; else None.
    rate: Optional[float] = None
    #: The units of the coordinates of a .c3d or .trc file ("mm", "m", ...); else None.
    units: Optional[str] = None
    #: From :meth:`Field.complete`: the weights of each filler per class of gap
    #: (``short``, ``long``, ``by_length``), and what each class's weights gave on the
    #: validation spans held out of their choice beside the best filler alone there
    #: (``held_out``: ``chosen``, ``best``, ``best_alone`` in the data's units, ``spans``);
    #: else None.
    blend: Optional[dict] = None


def read_tracks(
    path: PathLike,
    *,
    layout: Optional[str] = None,
    frame: Optional[str] = None,
    count_hidden: bool = False,
    confidence: Optional[str] = None,
    visibility_threshold: Optional[float] = None,
    model_outputs: bool = False,
) -> Tracks:
    """Reads ``.traj``, ``.anime``, ``.npy``, ``.npz`` (plain, PointOdyssey, TAPVid-3D,
    masked), ``.c3d`` or ``.trc`` (motion-capture markers in the file's units, with their
    ``labels``, ``rate`` and ``units``; a marker not measured in a frame is unobserved) or
    a folder of OBJ frames. Where the reader decided something about the file (a frame
    count read by its length, NaN coordinates read as missing), it says so once as a
    ``UserWarning``.

    A C3D file's model outputs (the points that ``POINT:ANGLES``, ``FORCES``,
    ``MOMENTS``, ``POWERS``, ... list, as Nexus stores joint angles and forces) are left
    out, as ``doma fit`` leaves them, and ``kept`` holds the file's index of each marker
    read; ``model_outputs=True`` reads every point.

    ``layout`` forces an ``.npz`` layout (default: detected from its keys); ``frame``
    (``world``/``camera``), ``count_hidden`` and ``confidence`` are those of ``doma fit``.
    A visibility is read by its dtype: bool as it is, integers 0 or 1, floats a
    probability in [0, 1] observed from ``visibility_threshold`` (default 0.5); any other
    value (a code such as 2 or -1, NaN) is refused, naming the entry.
    """
    choices = _lower_choices({"layout": layout, "frame": frame})
    positions, (t, n), observed, faces, weights, kept, named = _native.read_tracks(
        os.fspath(path),
        choices["layout"],
        choices["frame"],
        bool(count_hidden),
        confidence,
        visibility_threshold,
        bool(model_outputs),
    )
    return Tracks(
        tracks=np.frombuffer(positions, dtype=np.float32).reshape(t, n, 3),
        observed=np.frombuffer(observed, dtype=np.bool_).reshape(t, n),
        faces=None if faces is None else np.frombuffer(faces, dtype=np.uint32).reshape(-1, 3),
        weights=None if weights is None else np.frombuffer(weights, dtype=np.float32).reshape(t, n),
        kept=None if kept is None else np.frombuffer(kept, dtype=np.int64),
        labels=None if named is None else tuple(named[0]),
        rate=None if named is None else float(named[1]),
        units=None if named is None else named[2],
    )
