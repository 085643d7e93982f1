//! The memory check: a bake's estimated peak ([`plan::memory`]) against its limit
//! (`BakeConfig::max_memory`, or the memory the machine has available), before any heavy work:
//! before the atlas (texels predicted from the surface area), before light transport (texels
//! counted) and once the automatic choice has chosen the rays (where it may switch to the
//! matrix-free gather solver). A distributed bake's estimate is per process: its share of the
//! final rows, and whole what every process holds (scene, BVH, texels, pilot runs, the
//! radiosity vectors and the exchange's buffers).

use std::path::Path;

use crate::config::{BakeConfig, Technique};
use crate::plan::memory::Sizes;
use crate::plan::{self, MemoryEstimate, Plan, format_bytes};
use crate::{Error, Progress, Result, scene};

/// The memory a bake may use: `config.max_memory`, or what the machine has available now
/// (sysinfo; unlimited where it cannot tell).
pub(crate) fn limit(config: &BakeConfig) -> u64 {
    config.max_memory.unwrap_or_else(|| {
        let available = sysinfo::System::new().ok().map(|mut system| {
            system.refresh_memory();
            system.available_memory()
        });
        match available {
            Some(bytes) if bytes > 0 => bytes,
            _ => u64::MAX,
        }
    })
}

/// The peak a bake of `input` with `config` is expected to reach, in bytes, for running bakes
/// side by side (`build`): texels predicted from the surface area at the automatic density, a
/// pilot pair held while the final rows are built at the configured rays (the automatic choice
/// may choose others), the gather solver's peak where those rows would not fit the bake's limit
/// and it may switch; never above that limit (a bake that would exceed it is refused).
pub(crate) fn expected_peak(input: &Path, config: &BakeConfig) -> Result<u64> {
    let (scene, source) = scene::load(input)?;
    let mut config = config.clone();
    if let Some(auto) = config.auto {
        plan::choose_density(&scene, &mut config, &mut Plan::default(), &auto.keep);
    }
    let limit = limit(&config);
    let sizes = Sizes::predicted(&scene, &source, &config);
    let expected = sizes.expected(&config, limit as f64).total();
    Ok((expected.ceil() as u64).min(limit))
}

/// Refuses a bake of `sizes` that cannot fit in `limit` whatever the automatic choice does.
pub(crate) fn check(input: &Path, sizes: &Sizes, config: &BakeConfig, limit: u64) -> Result<()> {
    let least = sizes.least(config);
    refuse_above(input, sizes, &least, limit, config)
}

/// Once the rays are chosen (`pilot`: gathering rays of the last pilot pair's runs, whether
/// no further bake follows, and how many pilot runs the result averages; the plan's per-texel rays count when it has them): switches the automatic choice to the gather solver when the stored
/// rows do not fit and it does (with a warning), and refuses what still does not fit.
pub(crate) fn fit(
    input: &Path,
    sizes: &Sizes,
    config: &mut BakeConfig,
    plan: Option<&mut Plan>,
    pilot: Option<(u32, bool, usize)>,
    limit: u64,
    progress: &dyn Progress,
) -> Result<()> {
    let texel_rays = plan.as_ref().and_then(|p| p.texel_rays.as_ref());
    let rays = match texel_rays {
        Some(r) if !r.0.is_empty() => r.0.iter().map(|&k| k as f64).sum::<f64>() / r.0.len() as f64,
        _ => config.transport.gather_rays as f64,
    };
    let peaks = sizes.final_peaks(config.technique, rays, pilot);
    let mut plan = plan;
    if let (Some(plan), true) = (plan.as_deref_mut(), sizes.distributed()) {
        plan.reasons.push(format!(
            "memory: per process of {}: its share of the final rows, the rest whole (scene, \
             BVH, texels, pilot runs, radiosity vectors, exchange buffers)",
            sizes.processes
        ));
    }
    let storage = plan::choose_row_storage(
        &peaks.f32_rows,
        &peaks.count_rows,
        limit as f64,
        sizes.texels,
        config,
    );
    if let Some(plan) = plan.as_deref_mut() {
        plan.reasons.extend(storage);
    }
    let stored = peaks.stored(config.transport.count_rows);
    if let (Some(plan), Some(auto)) = (plan, config.auto)
        && let Some(message) = plan::fit_memory(
            &stored,
            &peaks.gather,
            limit as f64,
            config,
            plan,
            &auto.keep,
        )
    {
        progress.warn(&format!("{}: {message}", input.display()));
    }
    let chosen = if config.technique == Technique::Gather {
        peaks.gather
    } else {
        stored
    };
    refuse_above(input, sizes, &chosen, limit, config)
}

fn refuse_above(
    input: &Path,
    sizes: &Sizes,
    estimate: &MemoryEstimate,
    limit: u64,
    config: &BakeConfig,
) -> Result<()> {
    if estimate.total() <= limit as f64 {
        return Ok(());
    }
    let per_process = match sizes.distributed() {
        true => format!(" per process of {}", sizes.processes),
        false => String::new(),
    };
    let hint = if config.technique.is_monte_carlo() && config.technique != Technique::Gather {
        "lower --texels-per-unit or --rays, use --solver gather, or raise --max-memory"
    } else {
        "lower --texels-per-unit or --rays, or raise --max-memory"
    };
    Err(Error::Memory {
        path: input.to_path_buf(),
        message: format!(
            "the bake would need about {}{per_process} at its peak, above the memory limit \
             {} ({hint})",
            estimate.describe(),
            format_bytes(limit as f64)
        ),
    })
}
