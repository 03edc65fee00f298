//! `doma mesh-alignment`: Tab. 3 (guided alignment of the frame-0 template, Eq. 14).

use crate::Result;
use crate::cli::{AlignModelArgs, ExperimentArgs, SequenceArgs};
use crate::experiments::meshes::{self, AlignReg, MeshAlignmentJob};
use crate::jacobian::JacobianKind;
use crate::prelude::*;
use crate::register::RegistrationConfig;

/// The flags of `doma mesh-alignment`.
#[derive(clap::Parser, Debug, Clone)]
#[command(
    about = "Align the frame-0 template to every frame with guidance keypoints (paper Tab. 3)"
)]
pub struct MeshAlignmentArgs {
    /// The sequence.
    #[command(flatten)]
    pub sequence: SequenceArgs,
    /// The models.
    #[command(flatten)]
    pub models: AlignModelArgs,
    /// The regularisers (comma-separated): none, a (AIAP), h (smoothness), ah (both).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "none,a,h,ah")]
    pub reg: Vec<AlignReg>,
    /// Iterations per fit (the authors: 2000).
    #[arg(long, default_value_t = 2000, value_parser = clap::value_parser!(u64).range(1..))]
    pub iters: u64,
    /// Guidance keypoints: this many vertices, a fixed seeded subset.
    #[arg(long, default_value_t = 930, value_parser = clap::value_parser!(u64).range(1..))]
    pub keypoints: u64,
    /// Template surface samples (the authors: 10000).
    #[arg(long, default_value_t = 10_000, value_parser = clap::value_parser!(u64).range(2..))]
    pub canonical_samples: u64,
    /// Target surface samples per step (the authors: 10000).
    #[arg(long, default_value_t = 10_000, value_parser = clap::value_parser!(u64).range(1..))]
    pub target_samples: u64,
    /// Surface samples per mesh and frame for CD/CDN.
    #[arg(long, default_value_t = 40_000, value_parser = clap::value_parser!(u64).range(1..))]
    pub samples: u64,
    /// The SIREN's hidden width.
    #[arg(long, default_value_t = 128, value_parser = clap::value_parser!(u64).range(1..))]
    pub hidden: u64,
    /// Hidden sine layers after the first (the authors' registration: 3).
    #[arg(long, default_value_t = 3)]
    pub n_hidden: u64,
    /// How `L_H`'s Jacobian is computed; `analytic` also fuses the sine layers of every
    /// SIREN-based model's warp (DOMA and DPF).
    #[arg(long, value_enum, default_value = "autodiff")]
    pub jacobian: JacobianKind,
    /// Backend, seed, progress and JSON records.
    #[command(flatten)]
    pub common: ExperimentArgs,
}

impl MeshAlignmentArgs {
    /// The library job these flags describe (loads the sequence).
    pub fn job(&self) -> Result<MeshAlignmentJob> {
        let config = RegistrationConfig::new()
            .with_iterations(self.iters as usize)
            .with_canonical_samples(self.canonical_samples as usize)
            .with_target_samples(self.target_samples as usize)
            .with_jacobian(self.jacobian)
            .with_seed(self.common.seed);
        let job = MeshAlignmentJob {
            sequence: self.sequence.load(2)?,
            keypoints: self.keypoints as usize,
            models: self.models.model.clone(),
            regs: self.reg.clone(),
            config,
            aiap_weight: 1.0,
            h_weight: 0.001,
            hidden: self.hidden as usize,
            n_hidden: self.n_hidden as usize,
            samples: self.samples as usize,
            backend: self.common.backend,
            quiet: self.common.quiet,
        };
        // A model too large is refused naming the flags that sized it.
        for &model in &job.models {
            job.model(model, job.sequence.trajectories.frames())
                .validate()
                .map_err(|e| {
                    crate::DomaError::Usage(format!(
                        "--hidden {} --n-hidden {}: {}",
                        self.hidden,
                        self.n_hidden,
                        e.to_string().trim_start_matches("invalid configuration: ")
                    ))
                })?;
        }
        Ok(job)
    }
}

/// Runs every (model, regulariser) pair, then prints the table.
pub fn run(args: &MeshAlignmentArgs) -> Result<()> {
    args.common.check_json()?;
    let job = args.job()?;
    SequenceArgs::announce("mesh_alignment", &job.sequence, args.iters, job.backend);
    let records = meshes::mesh_alignment(&job, |r| {
        eprintln!(
            "{}{} CD {:.3}e-4 in {:.1} s",
            r.variant,
            r.reg.suffix(),
            r.cd_x1e4.unwrap_or(f64::NAN),
            r.seconds
        )
    })?;
    crate::cli::novel_points::finish(&records, &args.common)
}
