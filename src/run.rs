//! A fit of a user's own data, kept in a run folder (`doma fit`, `eval`, `warp`, `info`):
//!
//! | file | what |
//! |---|---|
//! | `config.json` | [`RunConfig`]: the data, the split, the normalisation and the [`FitConfig`] |
//! | `resume.ckpt` | the last checkpoint: parameters, Adam's state, the random stream, the history |
//! | `history.json` | one [`IterationRecord`] per finished iteration |
//! | `model.bpk` | the fitted field's parameters (burnpack), once the fit is done |
//! | `report.json` | [`Report`]: the metrics on the held-out points |
//!
//! Every file is written atomically. A checkpoint is written every `checkpoint_every`
//! iterations and on an interrupt; a resumed fit restores the parameters (with the ids
//! that key Adam's state), Adam's state and the random stream, so it reaches the same
//! weights as an uninterrupted fit on the same device. A non-finite loss stops the fit with
//! an error naming the iteration and leaves the last good checkpoint in place.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use crate::checkpoint::{Precision, decode_checkpoint, load_json, save_json};
use crate::data::Trajectories;
use crate::data::mesh::{TriMesh, as_points, encode_obj, read_obj, vertex_normals};
use crate::data::sequence::{Sequence, load_sequence, split_indices};
use crate::field::MotionField;
use crate::field::model::{Model, ModelConfig};
use crate::io::write_atomic;
use crate::metrics::{EPE_SCALE, epe_per_frame, predict};
use crate::train::{
    FitConfig, Hooks, IterationRecord, Outcome, RngState, Trainer, TrainerSnapshot,
};
use crate::{DomaError, Result};

/// What a run fits and how; saved as `config.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RunConfig {
    /// The data file or OBJ folder (absolute path).
    pub data: PathBuf,
    /// An OBJ for the faces, if given.
    pub mesh: Option<PathBuf>,
    /// The clip `[start, end)`, if any.
    pub frames: Option<[usize; 2]>,
    /// Every `stride`-th frame of the clip.
    pub stride: usize,
    /// The fraction of points held out for the report (the paper: 0.75).
    pub test_fraction: f64,
    /// Iterations between checkpoints.
    pub checkpoint_every: usize,
    /// The compute backend (a resumed fit uses the same one).
    #[serde(default = "default_backend")]
    pub backend: crate::backend::BackendKind,
    /// The fit (variant, iterations, learning rate, regularisers, seed, …).
    pub fit: FitConfig,
}

fn default_backend() -> crate::backend::BackendKind {
    crate::backend::BackendKind::Flex
}

impl RunConfig {
    /// A run of `data` with the given fit, the paper's 25 % / 75 % split and a checkpoint
    /// every 50 iterations.
    pub fn new(data: PathBuf, fit: FitConfig) -> Self {
        RunConfig {
            data,
            mesh: None,
            frames: None,
            stride: 1,
            test_fraction: 0.75,
            checkpoint_every: 50,
            backend: default_backend(),
            fit,
        }
    }

    /// Refuses values that cannot run.
    pub fn validate(&self) -> Result<()> {
        self.fit.validate()?;
        if !(self.test_fraction > 0.0 && self.test_fraction < 1.0) {
            return Err(DomaError::InvalidConfig(format!(
                "the test fraction {} must be strictly between 0 and 1",
                self.test_fraction
            )));
        }
        if self.checkpoint_every == 0 || self.stride == 0 {
            return Err(DomaError::InvalidConfig(
                "checkpoint interval and stride must be at least 1".into(),
            ));
        }
        Ok(())
    }

    /// Loads the run's data, normalised as when it was fitted.
    pub fn load(&self) -> Result<Sequence> {
        load_sequence(
            &self.data,
            self.mesh.as_deref(),
            self.frames.map(|[a, b]| a..b),
            self.stride,
        )
    }

    /// The training and held-out points of `data` (a seeded split).
    pub fn split(&self, data: &Trajectories) -> Result<(Trajectories, Trajectories)> {
        let (train, test) = split_indices(data.points(), 1.0 - self.test_fraction, self.fit.seed)?;
        Ok((data.select_points(&train)?, data.select_points(&test)?))
    }
}

/// The metrics of a fitted run; saved as `report.json`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Report {
    /// What was evaluated.
    pub evaluated_on: String,
    /// EPE × 10⁴ over all evaluated points and frames (normalised units).
    pub epe_x1e4: f64,
    /// EPE × 10⁴ per frame.
    pub epe_per_frame_x1e4: Vec<f64>,
    /// Frames evaluated.
    pub frames: usize,
    /// Points evaluated.
    pub points: usize,
    /// The field's parameter count.
    pub params: usize,
    /// The size of `model.bpk` in bytes.
    pub checkpoint_bytes: u64,
    /// Iterations fitted.
    pub iterations: usize,
    /// Seconds of fitting (over all resumed parts).
    pub seconds: f64,
}

/// The files of a run folder.
#[derive(Clone, Debug)]
pub struct RunDir {
    /// The folder.
    pub dir: PathBuf,
}

const MAGIC: &[u8; 8] = b"DOMARUN1";

/// The JSON part of `resume.ckpt`.
#[derive(Serialize, Deserialize)]
struct ResumeMeta {
    iterations_done: usize,
    history: Vec<IterationRecord>,
    rng: RngState,
}

impl RunDir {
    /// The run folder `dir`.
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        RunDir { dir: dir.into() }
    }
    /// `config.json`.
    pub fn config(&self) -> PathBuf {
        self.dir.join("config.json")
    }
    /// `model.bpk`.
    pub fn model(&self) -> PathBuf {
        self.dir.join("model.bpk")
    }
    /// `resume.ckpt`.
    pub fn resume(&self) -> PathBuf {
        self.dir.join("resume.ckpt")
    }
    /// `history.json`.
    pub fn history(&self) -> PathBuf {
        self.dir.join("history.json")
    }
    /// `report.json`.
    pub fn report(&self) -> PathBuf {
        self.dir.join("report.json")
    }

    /// The run's config; a folder without one is not a run.
    pub fn load_config(&self) -> Result<RunConfig> {
        let path = self.config();
        if !path.is_file() {
            return Err(DomaError::Malformed {
                path: self.dir.clone(),
                reason: "not a doma run folder (no config.json)".into(),
            });
        }
        let config: RunConfig = load_json(&path)?;
        config.validate().map_err(|e| DomaError::Malformed {
            path,
            reason: e.to_string(),
        })?;
        Ok(config)
    }

    /// The fitted field (from `model.bpk`, else from the last checkpoint, read in memory:
    /// nothing is written into the run folder).
    pub fn load_field(&self, config: &RunConfig, device: &Device) -> Result<Model> {
        let canonical = self.canonical_training_points(config)?;
        let fresh = config.fit.model.init(config.fit.seed, &canonical, device);
        let path = self.model();
        if path.is_file() {
            let bytes = std::fs::read(&path).map_err(|e| DomaError::io(&path, e))?;
            return fresh.decode(&bytes).map_err(|e| DomaError::Malformed {
                path,
                reason: e.to_string(),
            });
        }
        let snapshot = self.read_resume()?;
        decode_checkpoint(fresh, &snapshot.model).map_err(|e| DomaError::Malformed {
            path: self.resume(),
            reason: format!("the model part: {e}"),
        })
    }

    /// The canonical training points, which place BoneCloud's bones (the other models do
    /// not read them; the parameters come from the checkpoint anyway).
    fn canonical_training_points(&self, config: &RunConfig) -> Result<Vec<f32>> {
        if !matches!(config.fit.model, ModelConfig::BoneCloud(_)) {
            return Ok(Vec::new());
        }
        let sequence = config.load()?;
        Ok(config.split(&sequence.trajectories)?.0.frame(0).to_vec())
    }

    fn write_resume(&self, snapshot: &TrainerSnapshot) -> Result<()> {
        let meta = ResumeMeta {
            iterations_done: snapshot.iterations_done,
            history: snapshot.history.clone(),
            rng: snapshot.rng.clone(),
        };
        let json = serde_json::to_vec(&meta)
            .map_err(|e| DomaError::InvalidData(format!("cannot serialise the checkpoint: {e}")))?;
        let mut bytes = MAGIC.to_vec();
        for part in [&json, &snapshot.model, &snapshot.optimizer] {
            bytes.extend_from_slice(&(part.len() as u64).to_le_bytes());
            bytes.extend_from_slice(part);
        }
        write_atomic(&self.resume(), &bytes)
    }

    fn read_resume(&self) -> Result<TrainerSnapshot> {
        let path = self.resume();
        let bytes = std::fs::read(&path).map_err(|e| DomaError::io(&path, e))?;
        let bad = |reason: String| DomaError::Malformed {
            path: path.clone(),
            reason,
        };
        if bytes.len() < 8 || &bytes[..8] != MAGIC {
            return Err(bad("not a doma checkpoint (wrong magic)".into()));
        }
        let mut at = 8;
        let mut parts = Vec::with_capacity(3);
        for name in ["metadata", "model", "optimizer"] {
            let len = bytes
                .get(at..at + 8)
                .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
                .ok_or_else(|| bad(format!("truncated before the {name} length")))?;
            let end = usize::try_from(len)
                .ok()
                .and_then(|l| (at + 8).checked_add(l))
                .filter(|&e| e <= bytes.len())
                .ok_or_else(|| bad(format!("truncated: the {name} part is cut off")))?;
            parts.push(bytes[at + 8..end].to_vec());
            at = end;
        }
        if at != bytes.len() {
            return Err(bad(format!("{} trailing bytes", bytes.len() - at)));
        }
        let meta: ResumeMeta =
            serde_json::from_slice(&parts[0]).map_err(|e| bad(format!("bad metadata: {e}")))?;
        Ok(TrainerSnapshot {
            model: std::mem::take(&mut parts[1]),
            optimizer: std::mem::take(&mut parts[2]),
            rng: meta.rng,
            iterations_done: meta.iterations_done,
            history: meta.history,
        })
    }
}

/// How a fit ended.
#[derive(Clone, Debug, PartialEq)]
pub enum FitOutcome {
    /// All iterations ran; `model.bpk` and `report.json` are written.
    Finished(Report),
    /// Interrupted (e.g. Ctrl-C) after this many iterations; a checkpoint holds them.
    Interrupted {
        /// Iterations done and saved.
        iterations_done: usize,
    },
}

/// Fits `config` into `run` (a new or empty folder), or resumes the fit saved there when
/// `resume` is set. `interrupt` is polled after every iteration: when set, the fit saves a
/// checkpoint and returns [`FitOutcome::Interrupted`]. `stop_after` (for tests) interrupts
/// after that many iterations. `progress` shows a progress bar.
pub fn fit_run(
    run: &RunDir,
    config: Option<RunConfig>,
    device: &Device,
    interrupt: &AtomicBool,
    stop_after: Option<usize>,
    progress: bool,
) -> Result<FitOutcome> {
    let resume = config.is_none();
    let (config, sequence) = match config {
        Some(c) => {
            c.validate()?;
            if run.config().exists() {
                return Err(DomaError::InvalidConfig(format!(
                    "{} already holds a run; resume it with --resume or choose another folder",
                    run.dir.display()
                )));
            }
            // The data is checked before the folder is made, so that bad data leaves
            // nothing behind.
            let sequence = c.load()?;
            c.split(&sequence.trajectories)?;
            std::fs::create_dir_all(&run.dir).map_err(|e| DomaError::io(&run.dir, e))?;
            save_json(&c, &run.config())?;
            (c, sequence)
        }
        None => {
            let c = run.load_config()?;
            let sequence = c.load()?;
            (c, sequence)
        }
    };
    let (train, test) = config.split(&sequence.trajectories)?;
    let ad = device.clone().autodiff();
    let fit = &config.fit;
    let field = fit.model.init(fit.seed, train.frame(0), &ad);
    let mut trainer = Trainer::new(field, fit, &train, device)?.progress(progress);
    if resume && run.resume().is_file() {
        let snapshot = run.read_resume()?;
        trainer
            .restore(&snapshot)
            .map_err(|e| DomaError::Malformed {
                path: run.resume(),
                reason: e.to_string(),
            })?;
    }
    let mut hooks = Hooks::new()
        .checkpoint(config.checkpoint_every, |snapshot| {
            run.write_resume(snapshot)?;
            save_json(&snapshot.history, &run.history())
        })
        .interrupt(interrupt);
    if let Some(n) = stop_after {
        hooks = hooks.stop_after(n);
    }
    let fitted = match trainer.run_with(hooks)? {
        Outcome::Finished(fitted) => fitted,
        Outcome::Interrupted { iterations_done } => {
            return Ok(FitOutcome::Interrupted { iterations_done });
        }
    };
    let encoded = fitted.field.encode(Precision::F32)?;
    write_atomic(&run.model(), &encoded)?;
    let bytes = encoded.len() as u64;
    let report = evaluate(
        &fitted.field,
        &test,
        "the held-out points of the fitted data",
        device,
    )?;
    let report = Report {
        checkpoint_bytes: bytes,
        iterations: fitted.history.len(),
        seconds: fitted.seconds,
        ..report
    };
    save_json(&report, &run.report())?;
    Ok(FitOutcome::Finished(report))
}

/// The EPE report of `field` on `truth` (normalised coordinates).
pub fn evaluate(
    field: &dyn MotionField,
    truth: &Trajectories,
    what: &str,
    device: &Device,
) -> Result<Report> {
    let predicted = predict(field, truth, device)?;
    let per_frame: Vec<f64> = epe_per_frame(&predicted, truth)?
        .into_iter()
        .map(|e| e * EPE_SCALE)
        .collect();
    Ok(Report {
        evaluated_on: what.into(),
        epe_x1e4: per_frame.iter().sum::<f64>() / per_frame.len() as f64,
        epe_per_frame_x1e4: per_frame,
        frames: truth.frames(),
        points: truth.points(),
        params: field.param_count(),
        checkpoint_bytes: 0,
        iterations: 0,
        seconds: 0.0,
    })
}

/// The metrics of the run in `run`: on its own held-out points, or on every point of
/// `data` (normalised like the run's data).
pub fn eval_run(run: &RunDir, data: Option<&Path>, device: &Device) -> Result<Report> {
    let config = run.load_config()?;
    let field = run.load_field(&config, device)?;
    let own = config.load()?;
    let (truth, what) = match data {
        None => (
            config.split(&own.trajectories)?.1,
            "the held-out points of the fitted data".to_string(),
        ),
        Some(path) => {
            let other = load_sequence(path, None, None, 1)?;
            // Undo the other file's own normalisation, apply the run's.
            let denorm = denormalize(&other.trajectories, other.center, other.scale);
            (
                normalize_with(&denorm, own.center, own.scale),
                format!("every point of {}", path.display()),
            )
        }
    };
    let bytes = std::fs::metadata(run.model()).map(|m| m.len()).unwrap_or(0);
    let history: Vec<IterationRecord> = load_json(&run.history()).unwrap_or_default();
    let report = evaluate(&field, &truth, &what, device)?;
    Ok(Report {
        checkpoint_bytes: bytes,
        iterations: history.len(),
        seconds: history.last().map_or(0.0, |r| r.seconds),
        ..report
    })
}

fn map_points(t: &Trajectories, f: impl Fn(f32, usize) -> f32) -> Trajectories {
    let positions = t
        .positions()
        .iter()
        .enumerate()
        .map(|(i, &v)| f(v, i % 3))
        .collect();
    Trajectories::new(t.frames(), t.points(), positions).expect("an affine map keeps the shape")
}

fn denormalize(t: &Trajectories, center: [f32; 3], scale: f32) -> Trajectories {
    map_points(t, |v, c| v * scale + center[c])
}

fn normalize_with(t: &Trajectories, center: [f32; 3], scale: f32) -> Trajectories {
    map_points(t, |v, c| (v - center[c]) / scale)
}

/// Warps the canonical mesh `mesh` (in the data's own units; default: the run data's own
/// canonical frame with its faces) through the run's field to frames `frames` (default:
/// all of the run's frames) and writes `out/frame_0000.obj`, … with recomputed normals, each
/// atomically. Returns the paths written.
pub fn warp_run(
    run: &RunDir,
    mesh: Option<&Path>,
    out: &Path,
    frames: Option<std::ops::Range<usize>>,
    device: &Device,
) -> Result<Vec<PathBuf>> {
    let config = run.load_config()?;
    let field = run.load_field(&config, device)?;
    let own = config.load()?;
    let total = own.trajectories.frames();
    let range = frames.unwrap_or(0..total);
    if range.start >= range.end || range.end > total {
        return Err(DomaError::InvalidConfig(format!(
            "frames {}..{} are not within the run's {total} frames",
            range.start, range.end
        )));
    }
    let canonical = match mesh {
        Some(path) => read_obj(path)?,
        None => {
            let faces = own.faces.clone().ok_or_else(|| {
                DomaError::InvalidData(format!(
                    "{} has no faces: give the canonical mesh with --mesh",
                    config.data.display()
                ))
            })?;
            let vertices = as_points(own.trajectories.frame(0))
                .iter()
                .map(|p| std::array::from_fn(|c| p[c] * own.scale + own.center[c]))
                .collect();
            TriMesh { vertices, faces }
        }
    };
    let norm: Vec<[f32; 3]> = canonical
        .vertices
        .iter()
        .map(|v| std::array::from_fn(|c| (v[c] - own.center[c]) / own.scale))
        .collect();
    std::fs::create_dir_all(out).map_err(|e| DomaError::io(out, e))?;
    let mut paths = Vec::new();
    for k in range {
        let t = crate::data::normalized_time(k, total);
        let y = crate::warp::warp_points(&field, &norm, t, device)?;
        let vertices: Vec<[f32; 3]> = y
            .iter()
            .map(|p| std::array::from_fn(|c| p[c] * own.scale + own.center[c]))
            .collect();
        let warped = TriMesh {
            vertices,
            faces: canonical.faces.clone(),
        };
        let normals = vertex_normals(&warped.vertices, &warped.faces);
        let path = out.join(format!("frame_{k:04}.obj"));
        write_atomic(
            &path,
            encode_obj(&warped.vertices, &warped.faces, Some(&normals)).as_bytes(),
        )?;
        paths.push(path);
    }
    Ok(paths)
}

/// What `doma info` prints.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct RunInfo {
    /// The model's paper name (a DOMA variant's, or a baseline's).
    pub variant: String,
    /// The SIREN's hidden width (SIREN-based models).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub hidden: Option<usize>,
    /// Its hidden sine layers after the first.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub n_hidden: Option<usize>,
    /// Trainable parameters.
    pub params: usize,
    /// `model.bpk` bytes (0 before the fit finishes).
    pub checkpoint_bytes: u64,
    /// The data file.
    pub data: PathBuf,
    /// Frames and points of the (clipped) data.
    pub frames: usize,
    /// See `frames`.
    pub points: usize,
    /// Iterations done of those configured.
    pub iterations_done: usize,
    /// Iterations configured.
    pub iterations: usize,
}

/// Describes the run in `run`.
pub fn info(run: &RunDir) -> Result<RunInfo> {
    let config = run.load_config()?;
    let seq = config.load()?;
    let history: Vec<IterationRecord> = if run.history().is_file() {
        load_json(&run.history())?
    } else {
        Vec::new()
    };
    let model = &config.fit.model;
    let shape = match model {
        ModelConfig::Doma(c) => Some(&c.shape),
        ModelConfig::Dpf(c) => Some(&c.shape),
        _ => None,
    };
    Ok(RunInfo {
        variant: model.paper_name().into(),
        hidden: shape.map(|s| s.hidden),
        n_hidden: shape.map(|s| s.n_hidden),
        params: model.num_params(),
        checkpoint_bytes: std::fs::metadata(run.model()).map(|m| m.len()).unwrap_or(0),
        data: config.data.clone(),
        frames: seq.trajectories.frames(),
        points: seq.trajectories.points(),
        iterations_done: history.len(),
        iterations: config.fit.schedule.iterations,
    })
}

/// Writes the run's plots into `RUN_DIR/plots/`: `loss.png` (trajectory and total loss per
/// iteration, log scale), `epe_per_frame.png` (held-out EPE per frame) and, for each of
/// `frames` (default: the middle and the last frame), `points_frame_KKKK.png` (three views
/// of the held-out points coloured by error). Returns the paths written.
pub fn plot_run(run: &RunDir, frames: Option<&[usize]>, device: &Device) -> Result<Vec<PathBuf>> {
    use crate::plot::{Series, line_plot, three_views};
    let config = run.load_config()?;
    let field = run.load_field(&config, device)?;
    let seq = config.load()?;
    let (_, test) = config.split(&seq.trajectories)?;
    let history: Vec<IterationRecord> = load_json(&run.history())?;
    let dir = run.dir.join("plots");
    std::fs::create_dir_all(&dir).map_err(|e| DomaError::io(&dir, e))?;
    let mut written = Vec::new();

    let curve = |f: fn(&IterationRecord) -> f64| {
        history.iter().map(|r| (r.iteration as f64, f(r))).collect()
    };
    let loss = line_plot(
        "LOSS",
        "ITERATION",
        "LOSS (LOG)",
        &[
            Series {
                name: "TRAJECTORY L1",
                color: [40, 60, 200],
                points: curve(|r| r.trajectory_loss),
            },
            Series {
                name: "TOTAL",
                color: [210, 30, 30],
                points: curve(|r| r.total_loss),
            },
        ],
        true,
    );
    let path = dir.join("loss.png");
    loss.save(&path)?;
    written.push(path);

    let predicted = predict(&field, &test, device)?;
    let per_frame = epe_per_frame(&predicted, &test)?;
    let epe = line_plot(
        "HELD-OUT EPE PER FRAME",
        "FRAME",
        "EPE X1E-4",
        &[Series {
            name: "EPE",
            color: [30, 170, 90],
            points: per_frame
                .iter()
                .enumerate()
                .map(|(k, e)| (k as f64, e * EPE_SCALE))
                .collect(),
        }],
        false,
    );
    let path = dir.join("epe_per_frame.png");
    epe.save(&path)?;
    written.push(path);

    let t = test.frames();
    let default = [t / 2, t - 1];
    let chosen = frames.unwrap_or(&default);
    if let Some(&bad) = chosen.iter().find(|&&k| k >= t) {
        return Err(DomaError::InvalidConfig(format!(
            "frame {bad} is not within the run's {t} frames"
        )));
    }
    let canonical = as_points(test.frame(0));
    for &k in chosen {
        let (truth, pred) = (as_points(test.frame(k)), as_points(predicted.frame(k)));
        let mut errors: Vec<f64> = truth
            .iter()
            .zip(&pred)
            .map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).abs() as f64).sum())
            .collect();
        errors.sort_by(f64::total_cmp);
        // The colour scale ends at the 99th percentile, so that one outlier does not wash
        // out the rest.
        let max = errors[(errors.len() - 1) * 99 / 100];
        let title = format!("FRAME {k}: EPE {:.1} X1E-4", per_frame[k] * EPE_SCALE);
        let path = dir.join(format!("points_frame_{k:04}.png"));
        three_views(&title, &canonical, &truth, &pred, max).save(&path)?;
        written.push(path);
    }
    Ok(written)
}
