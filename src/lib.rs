//! # lightbake — a lightmap baker
//!
//! lightbake takes a glTF scene and gives back the same scene with lightmap UVs (`TEXCOORD_1`),
//! OpenEXR lightmap pages and a glTF that references them. Diffuse global illumination is solved
//! by radiosity: every lightmap texel is a patch, form factors between texels come from
//! ray-cast visibility, and the system is iterated to a residual tolerance.
//!
//! How to use it — the output contract, the options, engines, the build step — is the user
//! [`guide`] (the README and its chapters, with every example compiled).
//!
//! ## Pipeline
//!
//! Each stage is a plain data type in and a plain data type out; the module tree follows it:
//!
//! ```text
//!  input.gltf ─ scene::load ──▶ Scene + Source        world-space triangles, materials, lights,
//!                                                     cameras (all a renderer needs)
//!   ─ plan::choose_density ──▶ BakeConfig            texel density for the scene's area (auto)
//!  ─ scene::junctions::split ▶ Scene                 receivers cut where other surfaces meet
//!                                                     them (new vertices are blends: provenance;
//!                                                     instances in parallel), and along the hard
//!                                                     shadow outlines of punctual lights
//!                                                     (scene::shadow_cuts; its
//!                                                     shadow rays come from a Tracer of the
//!                                                     uncut scene, passed in by `bake`);
//!                                                     with --near-contacts, along the outlines
//!                                                     of surfaces facing them from under a
//!                                                     texel away too
//!             Tracer::new   ──▶ Tracer                obvhs CWBVH: closest hit, occlusion
//!    ─ atlas::slots::density ─▶ a density factor per  faces narrower than four texels near an
//!                               triangle              emitter: four texels across;
//!                                                     with --near-contacts, slot faces: a texel
//!                                                     no wider than the gap
//!            ─ atlas::build ──▶ Atlas                 xatlas charts + pages, or input TEXCOORD_1;
//!                                                     meshes far finer than a texel charted by
//!                                                     smooth patches, xatlas packing them;
//!                                                     with --instancing share, one layout per
//!                                                     mesh several nodes place and a page rect
//!                                                     per node (atlas::share; the junction
//!                                                     split leaves those instances whole)
//!           ─ texels::build ──▶ Texels                one radiosity patch per covered texel
//!       ─ texels::validity ──▶ Texels                 samples moved out of geometry, invalid marked,
//!                                                     texels a wall divides kept to one side (cuts)
//!  ─ pilot + plan::density ──▶ a density factor per region (connected surface between
//!                                                     creases) where the lookup error of a pilot
//!                                                     pair sits, measured on a uniform atlas of
//!                                                     its own at half the preset's density or
//!                                                     coarser (atlas::build_quick: planar regions
//!                                                     and smooth patches, shelf-packed by
//!                                                     atlas::pack); ×⅛ on what nobody sees; the
//!                                                     three stages above then run once with the
//!                                                     factors (auto, adaptive). A small scene is
//!                                                     measured on the final uniform atlas, kept
//!                                                     with its pilot pair when the factors asked
//!                                                     move under 5% of its texels
//!   (all of the above is `prepare`, shared by the bake and the reference)
//!    ─ pilot runs + plan   ──▶ BakeConfig + pilot    rays for the target error after
//!                                                     denoising, measured (auto); the lookup
//!                                                     error read at the density pilot's points
//!                                                     against the light it gathered there; when
//!                                                     that predicts the target missed by texels,
//!                                                     the atlas is laid out again once and
//!                                                     planned again (`bake::light`)
//!  ─ one dispatch on config::Technique:
//!        ─ transport::build ──▶ Transport             form factors F_ij (CSR rows) + H_direct
//!            ─ solve::solve ──▶ Solution              H = H_direct + F·(ρH), iterated
//!     or solve::gather, solve::hierarchical ──▶ Transport (no rows) + Solution
//!     ─ lightmap::denoise  ──▶ H/π per texel         edge-aware, Monte Carlo only
//!  ─ lightmap::directional ──▶ L1 SH per texel       with --directional: a final gather over
//!                                                     the solution (pages like the lightmap's)
//!           ─ probes::bake ──▶ Probes                with --probes: a grid of L2 SH light
//!                                                     probes in the empty space (as many
//!                                                     as a tenth of the bake's rays
//!                                                     afford), its cells
//!                                                     divided where light changes, level by
//!                                                     level (or where a node says,
//!                                                     --probes-from), buried ones
//!                                                     marked, gathered from the solution
//! ─ LightmapPages::from_texels ▶ LightmapPages         H/π per texel, dilated into the gutters
//!         ─ lightmap::seams ──▶ LightmapPages         UV seams stitched (least squares)
//!                  ─ output ──▶ .exr + .png pages, .gltf/.bin or .glb (every file format
//!                                                     lightbake writes: exr, png, rgbm, glb, gltf;
//!                                                     with probes their .json and, on a grid,
//!                                                     Bevy's irradiance volume, probes::volume)
//! ```
//!
//! [`bake`] chains the stages ([`prepare`], [`compute`], [`write()`]); build tools that want the
//! intermediate data call them directly. [`build()`] bakes the scenes of a [`Manifest`] that
//! changed since their last bake ([`mod@build`]), incrementally ([`incremental`]) where only
//! node transforms changed or nodes were removed or added. Stages call only downwards:
//!
//! ```text
//!   error, progress, sampling        below everything
//!   config                           all options: Technique (only valid transport × solver
//!                                    pairs), AutoParams/Keep of the automatic choice
//!   scene → trace → atlas → texels → lights
//!   transport                        rows (one chunked row builder; `storage`: f32 weights, or
//!                                    Monte Carlo rows as exact ray counts when the planner finds
//!                                    f32 rows do not fit the memory budget or `--rows counts`
//!                                    asks), montecarlo, point,
//!                                    polygon, hierarchical link building and direct light
//!   solve                            one stopping rule; jacobi, gauss_seidel, southwell on stored
//!                                    rows; gather (matrix-free) and hierarchical make their own
//!                                    transport as they iterate
//!   lightmap, probes, output
//!   plan                             pure decisions of the automatic choice (no solving),
//!                                    the estimate of a bake's peak memory
//!   bake                             prepare/compute/write; `light`: the one dispatch of a
//!                                    Technique to transport and solver, on the `Processes` a
//!                                    bake runs on (one, or a distributed bake's); `pilot`: the pilot runs
//!                                    and the final bake that reuses them; `memory`: the
//!                                    estimate against `--max-memory` (refuse, or gather);
//!                                    `kept`: the kept transport's file (`--keep-transport`);
//!                                    `relight`: a kept bake solved again with other light and
//!                                    material values, and per-light layers;
//!                                    `incremental`: a kept bake re-baked after nodes moved,
//!                                    were removed or were added (`bake --since`): the old
//!                                    layout made again (a removed node's texels kept, unused;
//!                                    an added node's charts unwrapped onto pages after the
//!                                    old ones, its rows traced whole), only the rays that meet
//!                                    a moved node's old or new bounds, a removed one's old
//!                                    bounds or an added one's bounds traced again (drawn from
//!                                    their seeds, nothing per ray kept);
//!                                    `distributed`: the same bake over several processes
//!                                    (timely dataflow): every transport's rows (pilots' and
//!                                    final) sharded, the radiosity vector exchanged every
//!                                    sweep, process 0 finishes and writes
//!   shard                            per-item work (validity probes, the planner's samples)
//!                                    divided among a bake's processes and gathered
//!   build                            many scenes from a manifest: `bake` options by name, a
//!                                    content-addressed cache, a JSON report, the error gate
//!   reference, render                beside the pipeline (reference uses bake's prepare)
//!   view                             the viewer page: a bake in three.js, served on 127.0.0.1
//! ```
//!
//! Beside the pipeline: [`reference`](mod@reference) (the path tracer every accuracy figure is measured
//! against, at texels or through a camera), [`render`] (lightmapped views with a ray-traced
//! specular layer; it reads only the [`scene::Scene`] and the EXR pages its instances name,
//! never glTF JSON) and [`metrics`] (the error measures of every accuracy figure). The
//! reference also measures what a renderer shows: [`reference::points`] path-traces random
//! visible surface points (over the whole scene, or within a [`reference::points::Strip`] beside
//! a wall, where leaks would show) and reads the written bake there as a renderer does
//! (`TEXCOORD_1`, bilinear lookup in the EXR page). [`probes`] carries the solved light to
//! points off the surfaces (what moves), read back through [`render::RenderScene`] and
//! measured at free-space points by [`reference::points::trace_about`] (the true irradiance)
//! and [`reference::trace_sh`] (the L2 projection a probe can hold at best);
//! [`probes::for_bake`] gathers probes of other parameters for a finished bake. [`view`] serves a page that shows a bake in a browser with
//! three.js (vendored, offline), loaded exactly as a three.js user would load it, and with
//! probes a sphere they light, moved by the user.
//!
//! ## Conventions
//!
//! Units are radiometric, linear Rec.709 RGB. Emitted radiance is
//! `emissiveFactor × emissiveStrength`; reflectance is `baseColorFactor × baseColorTexture`
//! (clamped to [`scene::MAX_ALBEDO`]). A lightmap texel stores `H/π` — the radiance a white
//! Lambertian surface would reflect — so a renderer shades `baseColor × lightmap + emission`.
//! Lightmap UVs are in `TEXCOORD_1`, glTF image convention (v down, EXR row 0 at the top).
//!
//! ## Determinism
//!
//! Every random number comes from a stream seeded by (seed, texel, sample); parallel loops
//! collect in order. The same input and options give the same bytes on any thread count.

#![warn(missing_docs)]

pub mod atlas;
pub mod build;
pub mod config;
pub(crate) mod error;
pub mod guide;
pub mod lightmap;
pub(crate) mod lights;
pub mod metrics;
pub mod output;
pub mod plan;
pub mod probes;
pub mod progress;
pub mod reference;
pub mod render;
pub mod sampling;
pub mod scene;
pub(crate) mod shard;
pub mod solve;
pub mod texels;
pub mod trace;
pub mod transport;
pub mod view;

#[cfg(feature = "testing")]
#[doc(hidden)]
pub mod testing;

mod bake;

pub use bake::{
    BakeReport, Baked, Prepared, ProbeCount, StageTime, bake, compute, distributed, incremental,
    kept, prepare, relight, split_junctions, write,
};
pub use build::{BuildReport, Manifest, build};
pub use config::BakeConfig;
pub use error::{Error, Result};
pub use progress::{NoProgress, Progress};
