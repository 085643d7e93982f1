//! The single integration-test binary (one link step; `autotests = false` in Cargo.toml).

mod util;

mod analytic;
mod build;
mod cli;
mod denoise;
mod dense;
mod directional;
mod distributed;
mod docs;
mod form_factors;
mod hardening;
mod hierarchical;
mod house;
mod incremental;
mod instancing;
mod junctions;
mod narrow_faces;
mod pipeline;
mod plan;
mod points;
mod probes;
mod quality;
mod reference;
mod relight;
mod render;
mod seams;
mod shadow_cuts;
mod solvers;
mod view;
