//! The `doma` binary as a user runs it: every subcommand, bad flags and files, signals,
//! batch shards, the glTF export (with the Khronos validator) and the viewer (in headless
//! Chromium); and what a file names never reaches outside where the user pointed.

#[path = "../common/mod.rs"]
mod common;

mod batch;
mod cli;
mod export;
mod reliability;
mod security;
mod view;
