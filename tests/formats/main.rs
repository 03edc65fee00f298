//! The file formats and data: `.traj`, `.anime`, `.npy`/`.npz`, C3D, OBJ meshes and sequences,
//! the synthetic benchmark's data; round trips, shipped files, and every bad file refused
//! with an error naming the file and the problem.

#[path = "../common/mod.rs"]
mod common;

mod anime;
mod c3d;
mod data;
mod mesh;
mod npy;
mod tracks;
mod traj;
