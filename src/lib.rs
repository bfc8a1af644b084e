//! arlux: per-pixel differential rendering. Inserts virtual objects and
//! lights into a photograph of a real room, with their shadows and indirect
//! light, after Grosch et al. 2003 and Loscos et al. 2000.
//!
//! Data flows one way: [`scene`] → estimates → radiosity → pixel data →
//! composite. Each stage is a module taking plain data and returning plain data.
//! Ray tracing is Embree's, bound in [`trace`] (the crate's only `unsafe`,
//! which the compiler enforces: every other module is under `deny(unsafe_code)`).

#![deny(unsafe_code)]

pub mod blocks;
pub mod camera;
pub mod compare;
pub mod composite;
pub mod error;
pub mod estimate;
pub mod gather;
pub mod geometry;
pub mod gonio;
pub mod hdr;
pub mod ies;
pub mod image_io;
pub mod inputs;
pub mod interactive;
pub mod lamps;
pub mod light;
pub mod materials;
pub mod model;
pub mod object_shading;
pub mod objects;
pub mod output;
pub mod patches;
pub mod pda;
pub mod placement;
pub mod radiosity;
pub mod relight;
pub mod render;
pub mod renderer;
pub mod residual;
pub mod scene;
pub mod scene_tracer;
pub mod settings;
pub mod shadows;
pub mod shaft;
pub mod surface_ids;
pub mod sweep;
#[allow(unsafe_code)]
pub mod trace;
pub mod util;

pub use error::{Error, Result};
