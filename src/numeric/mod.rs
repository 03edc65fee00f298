//! Numerics on the host, on plain slices: nearest neighbours ([`knn`]), the symmetric
//! eigenproblem and principal components ([`eigen`]), and the small dense solvers
//! ([`linalg`]: the spline's tridiagonal system, least squares on the simplex, a Gram
//! matrix). A leaf of the crate: it imports nothing of doma but the error type, so that
//! gap filling, the losses, the metrics and the trainer's SOAP basis share it without
//! importing one another.

pub mod eigen;
pub mod knn;
pub mod linalg;
