//! Measured and modelled scaling of a distributed bake (issue 15): one process against two
//! on this machine, a cost model calibrated from them, and its prediction for 8–64 machines on
//! a 10-million-texel scene, with a chart.
//!
//! ```text
//! cargo run --release --example distributed_scaling -- BIN SCENE OUT RUNS [BAKE OPTION...]
//! cargo run --release --example distributed_scaling -- --from OUT/distributed_scaling.csv
//! ```
//!
//! The first form bakes SCENE with BIN as 1 and as 2 processes (`--hosts` on loopback, each
//! process under `/usr/bin/time` for its wall time and peak resident memory, one thread each),
//! RUNS times each, interleaved; it reads each process's own line (rows built, seconds of row
//! building, sweeps, seconds in exchanges, bytes sent per sweep, counted by the library) and
//! process 0's stage times, and writes them to `OUT/distributed_scaling.csv`. Both forms then
//! calibrate the model from the means and print it; the chart goes to
//! `examples/gallery/distributed_scaling.png`.
//!
//! The model, per machine of P, for a scene of N texels (one thread per machine, as measured):
//!
//! - prepare (load, junctions, BVH, atlas, texels, validity) and plan (the density pilot and
//!   the ray pilots with their samples): each `(s + d/P)·N`, a serial part `s` every machine
//!   does whole (loading, the atlases, the sweeps' whole-vector work, the planner's arithmetic)
//!   and a divided part `d` (rays: validity probes, pilot rows, point samples), calibrated from
//!   the one- and two-process runs (`s = 2·T₂ − T₁`, `d = T₁ − s`, per texel);
//! - rows: `t_row·N/P`;
//! - sweeps: `S·(t_gather·N/P + t_vector·N)`: each sweep gathers its rows and then reads the
//!   whole vector (radiosity, the stopping sums);
//! - exchange: `S·(latency + 12·N·(P−1)/P / bandwidth)`: each machine receives every other
//!   machine's slice of H (3 floats a texel) per sweep;
//! - finish on process 0 (denoise, dilate, seams, write): `t_finish·N`;
//! - memory: `m_shared·N + m_rows·N/P`, from the two runs' peaks (rows split, the rest whole).

use std::fmt::Write as _;
use std::path::Path;
use std::process::{Command, Stdio};

use plotters::prelude::*;

#[path = "../benchmark/font.rs"]
mod font;

/// One process of one measured bake.
#[derive(Clone, Debug)]
struct Sample {
    processes: usize,
    run: usize,
    process: usize,
    texels: usize,
    wall: f64,
    peak_mb: f64,
    rows: usize,
    rows_seconds: f64,
    sweeps: usize,
    sweeps_seconds: f64,
    exchange_seconds: f64,
    bytes_per_sweep: u64,
    /// Process 0 only: the stages before light transport but the plan's, the plan's (density
    /// pilot, ray pilots), and those after light transport.
    prepare_seconds: f64,
    plan_seconds: f64,
    finish_seconds: f64,
}

const CSV_HEADER: &str = "processes,run,process,texels,wall_s,peak_mb,rows,rows_s,sweeps,sweeps_s,exchange_s,bytes_per_sweep,prepare_s,plan_s,finish_s";

/// Network of the modelled machines.
const BANDWIDTHS: [(&str, f64); 2] = [("10 Gbit/s", 1.25e9), ("1 Gbit/s", 1.25e8)];
const LATENCY: f64 = 100e-6;
const TEXELS: f64 = 10e6;
const MACHINES: [usize; 4] = [8, 16, 32, 64];

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let samples = match &args[..] {
        [from, csv] if from == "--from" => read_csv(&std::fs::read_to_string(csv).expect("CSV")),
        [bin, scene, out, runs, options @ ..] => {
            let samples = measure(
                bin,
                Path::new(scene),
                Path::new(out),
                runs.parse().unwrap(),
                options,
            );
            std::fs::write(
                Path::new(out).join("distributed_scaling.csv"),
                to_csv(&samples),
            )
            .expect("write the CSV");
            samples
        }
        _ => panic!("usage: distributed_scaling BIN SCENE OUT RUNS [BAKE OPTION...] | --from CSV"),
    };
    print_measured(&samples);
    let model = Model::calibrate(&samples);
    print!("{}", model.describe());
    print_predictions(&model);
    let chart_path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/gallery/distributed_scaling.png");
    chart(&chart_path, &model).expect("chart");
    println!("chart: {}", chart_path.display());
}

/// Bakes `runs` times as 1 and as 2 processes, interleaved.
fn measure(bin: &str, scene: &Path, out: &Path, runs: usize, options: &[String]) -> Vec<Sample> {
    std::fs::create_dir_all(out).expect("OUT");
    let mut samples = Vec::new();
    for run in 0..runs {
        for processes in [1, 2] {
            samples.extend(bake(bin, scene, out, processes, run, options));
        }
    }
    samples
}

/// One bake as `processes` processes of a hosts file on loopback.
fn bake(
    bin: &str,
    scene: &Path,
    out: &Path,
    processes: usize,
    run: usize,
    options: &[String],
) -> Vec<Sample> {
    let listeners: Vec<_> = (0..processes)
        .map(|_| std::net::TcpListener::bind("127.0.0.1:0").unwrap())
        .collect();
    let hosts: Vec<String> = listeners
        .iter()
        .map(|l| l.local_addr().unwrap().to_string())
        .collect();
    drop(listeners);
    let hosts_file = out.join("hosts");
    std::fs::write(&hosts_file, hosts.join("\n")).unwrap();
    let dir = out.join(format!("bake_p{processes}_r{run}"));
    let _ = std::fs::remove_dir_all(&dir);
    let children: Vec<_> = (0..processes)
        .map(|p| {
            Command::new("/usr/bin/time")
                .args(["-f", "%e %M", bin, "bake"])
                .arg(scene)
                .arg("-o")
                .arg(&dir)
                .args(options)
                .args(["--threads", "1", "--hosts"])
                .arg(&hosts_file)
                .args(["--process", &p.to_string()])
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .expect("run the bake")
        })
        .collect();
    let outputs: Vec<_> = children
        .into_iter()
        .map(|c| c.wait_with_output().unwrap())
        .collect();
    outputs
        .iter()
        .enumerate()
        .map(|(process, o)| {
            let stdout = String::from_utf8_lossy(&o.stdout);
            let stderr = String::from_utf8_lossy(&o.stderr);
            assert!(o.status.success(), "process {process} failed: {stderr}");
            let mut time = stderr.lines().last().unwrap_or_default().split_whitespace();
            let wall = time.next().unwrap().parse().unwrap();
            let peak_mb = time.next().unwrap().parse::<f64>().unwrap() / 1024.0;
            let mine = stdout
                .lines()
                .find(|l| l.starts_with(&format!("process {process} of")))
                .expect("the process line");
            let numbers: Vec<f64> = mine
                .replace("..", " ")
                .split(|c: char| !(c.is_ascii_digit() || c == '.'))
                .filter_map(|w| w.trim_end_matches('.').parse().ok())
                .collect();
            // process P of N: rows A..B built in Rs, S sweeps in Ts (Es of it in exchanges), X bytes …
            let [_, _, a, b, rows_s, sweeps, sweeps_s, exchange_s, bytes, ..] = numbers[..] else {
                panic!("unexpected process line: {mine}")
            };
            let summary = stdout
                .lines()
                .find(|l| l.contains(" texels ("))
                .unwrap_or_default();
            let stage = |name: &str| -> f64 {
                summary
                    .split([',', ';', '('])
                    .filter_map(|part| part.trim().strip_prefix(&format!("{name} ")))
                    .filter_map(|v| v.trim_end_matches('s').parse::<f64>().ok())
                    .sum()
            };
            let texels = summary
                .split(" texels")
                .next()
                .and_then(|n| n.parse().ok())
                .unwrap_or(0);
            let prepare = ["load", "junctions", "bvh", "atlas", "texels", "validity"];
            let plan = ["density pilot", "plan"];
            let finish = ["denoise", "dilate", "seams", "write"];
            Sample {
                processes,
                run,
                process,
                texels,
                wall,
                peak_mb,
                rows: (b - a) as usize,
                rows_seconds: rows_s,
                sweeps: sweeps as usize,
                sweeps_seconds: sweeps_s,
                exchange_seconds: exchange_s,
                bytes_per_sweep: bytes as u64,
                prepare_seconds: prepare.iter().map(|s| stage(s)).sum(),
                plan_seconds: plan.iter().map(|s| stage(s)).sum(),
                finish_seconds: finish.iter().map(|s| stage(s)).sum(),
            }
        })
        .collect()
}

fn to_csv(samples: &[Sample]) -> String {
    let mut csv = format!("{CSV_HEADER}\n");
    for s in samples {
        let _ = writeln!(
            csv,
            "{},{},{},{},{:.2},{:.1},{},{:.3},{},{:.3},{:.3},{},{:.3},{:.3},{:.3}",
            s.processes,
            s.run,
            s.process,
            s.texels,
            s.wall,
            s.peak_mb,
            s.rows,
            s.rows_seconds,
            s.sweeps,
            s.sweeps_seconds,
            s.exchange_seconds,
            s.bytes_per_sweep,
            // + 0.0: an empty sum is −0.0 (process 1 prints no stage times).
            s.prepare_seconds + 0.0,
            s.plan_seconds + 0.0,
            s.finish_seconds + 0.0
        );
    }
    csv
}

fn read_csv(text: &str) -> Vec<Sample> {
    text.lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|line| {
            let v: Vec<&str> = line.split(',').collect();
            let f = |i: usize| v[i].parse::<f64>().unwrap();
            Sample {
                processes: f(0) as usize,
                run: f(1) as usize,
                process: f(2) as usize,
                texels: f(3) as usize,
                wall: f(4),
                peak_mb: f(5),
                rows: f(6) as usize,
                rows_seconds: f(7),
                sweeps: f(8) as usize,
                sweeps_seconds: f(9),
                exchange_seconds: f(10),
                bytes_per_sweep: f(11) as u64,
                prepare_seconds: f(12),
                plan_seconds: f(13),
                finish_seconds: f(14),
            }
        })
        .collect()
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = values.collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Mean of `field` over the samples of `processes` processes (and process `process`, if given).
fn mean_of(
    samples: &[Sample],
    processes: usize,
    process: Option<usize>,
    field: impl Fn(&Sample) -> f64,
) -> f64 {
    mean(
        samples
            .iter()
            .filter(|s| s.processes == processes && process.is_none_or(|p| s.process == p))
            .map(field),
    )
}

fn print_measured(samples: &[Sample]) {
    println!("measured (mean of the runs; one thread per process):");
    println!(
        "| processes | process | rows | wall s | peak MB | rows s | sweeps | sweeps s | in exchanges s | bytes sent per sweep |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for processes in [1, 2] {
        for process in 0..processes {
            let m = |f: &dyn Fn(&Sample) -> f64| mean_of(samples, processes, Some(process), f);
            println!(
                "| {processes} | {process} | {:.0} | {:.2} | {:.0} | {:.2} | {:.0} | {:.2} | {:.2} | {:.0} |",
                m(&|s| s.rows as f64),
                m(&|s| s.wall),
                m(&|s| s.peak_mb),
                m(&|s| s.rows_seconds),
                m(&|s| s.sweeps as f64),
                m(&|s| s.sweeps_seconds),
                m(&|s| s.exchange_seconds),
                m(&|s| s.bytes_per_sweep as f64),
            );
        }
    }
    let wall = |p| mean(samples.iter().filter(|s| s.processes == p).map(|s| s.wall));
    println!(
        "wall time, 2 processes against 1: {:.2} s / {:.2} s = {:.2}×\n",
        wall(2),
        wall(1),
        wall(2) / wall(1)
    );
}

/// Per-texel costs calibrated from the runs.
struct Model {
    texels: f64,
    sweeps: f64,
    /// Seconds per texel (one thread): (every machine's, divided among the machines).
    prepare: (f64, f64),
    plan: (f64, f64),
    rows: f64,
    gather: f64,
    vector: f64,
    finish: f64,
    /// Bytes per texel: held whatever P, and the rows (divided by P).
    shared_bytes: f64,
    row_bytes: f64,
    /// How much slower the slower of the two processes built its rows than their mean.
    imbalance: f64,
}

impl Model {
    fn calibrate(samples: &[Sample]) -> Model {
        let n = mean_of(samples, 1, Some(0), |s| s.texels as f64);
        let sweeps = mean_of(samples, 1, Some(0), |s| s.sweeps as f64);
        let one = |f: &dyn Fn(&Sample) -> f64| mean_of(samples, 1, Some(0), f);
        let two = |f: &dyn Fn(&Sample) -> f64| mean_of(samples, 2, None, f);
        // Sweep compute without the exchange, per sweep: a·n/P + b·n, from P = 1 and 2.
        let compute = |s: &Sample| (s.sweeps_seconds - s.exchange_seconds) / s.sweeps as f64;
        let (c1, c2) = (one(&compute), two(&compute));
        let gather = (2.0 * (c1 - c2)).max(0.0) / n;
        let vector = (c1 / n - gather).max(0.0);
        let (m1, m2) = (one(&|s| s.peak_mb), two(&|s| s.peak_mb));
        let row_bytes = (2.0 * (m1 - m2)).max(0.0) * 1048576.0 / n;
        let shared_bytes = (m1 * 1048576.0 / n - row_bytes).max(0.0);
        let rows_2: Vec<f64> = (0..2)
            .map(|p| mean_of(samples, 2, Some(p), |s| s.rows_seconds))
            .collect();
        let imbalance = rows_2.iter().cloned().fold(0.0, f64::max) / mean(rows_2.iter().cloned());
        // Stage times are process 0's (the others print no summary).
        let split = |f: &dyn Fn(&Sample) -> f64| {
            let (t1, t2) = (one(f), mean_of(samples, 2, Some(0), f));
            let serial = (2.0 * t2 - t1).clamp(0.0, t1);
            (serial / n, (t1 - serial) / n)
        };
        Model {
            texels: n,
            sweeps,
            prepare: split(&|s| s.prepare_seconds),
            plan: split(&|s| s.plan_seconds),
            rows: one(&|s| s.rows_seconds) / n,
            gather,
            vector,
            finish: one(&|s| s.finish_seconds) / n,
            shared_bytes,
            row_bytes,
            imbalance,
        }
    }

    fn describe(&self) -> String {
        format!(
            "calibrated on {:.0} texels, {:.0} sweeps:\n  prepare {:.2} µs/texel on every machine + {:.2} divided, \
             plan {:.2} µs/texel on every machine + {:.2} divided, rows {:.1} µs/texel, \
             sweep gather {:.3} µs/texel/sweep, whole-vector work {:.3} µs/texel/sweep, finish {:.2} µs/texel (process 0)\n  \
             memory: {:.0} B/texel held by every machine, {:.0} B/texel of rows (split)\n  \
             row-building imbalance of the two processes: slower one at {:.2}× their mean\n\n",
            self.texels,
            self.sweeps,
            self.prepare.0 * 1e6,
            self.prepare.1 * 1e6,
            self.plan.0 * 1e6,
            self.plan.1 * 1e6,
            self.rows * 1e6,
            self.gather * 1e6,
            self.vector * 1e6,
            self.finish * 1e6,
            self.shared_bytes,
            self.row_bytes,
            self.imbalance
        )
    }

    /// Seconds per stage on one of `p` machines for `n` texels: prepare, plan, rows, sweeps,
    /// exchange, finish.
    fn time(&self, n: f64, p: usize, bandwidth: f64) -> [f64; 6] {
        let pf = p as f64;
        let exchange = if p > 1 {
            self.sweeps * (LATENCY + 12.0 * n * (pf - 1.0) / pf / bandwidth)
        } else {
            0.0
        };
        let shared = |(serial, divided): (f64, f64)| (serial + divided / pf) * n;
        [
            shared(self.prepare),
            shared(self.plan),
            self.rows * n / pf,
            self.sweeps * (self.gather * n / pf + self.vector * n),
            exchange,
            self.finish * n,
        ]
    }

    fn memory(&self, n: f64, p: usize) -> f64 {
        self.shared_bytes * n + self.row_bytes * n / p as f64
    }
}

const STAGES: [&str; 6] = ["prepare", "plan", "rows", "sweeps", "exchange", "finish"];

fn print_predictions(model: &Model) {
    for (name, bandwidth) in BANDWIDTHS {
        println!(
            "predicted for {:.0} M texels, {name}, latency {:.0} µs, one thread a machine:",
            TEXELS * 1e-6,
            LATENCY * 1e6
        );
        println!(
            "| machines | prepare s | plan s | rows s | sweeps s | exchange s | finish s | total s | memory / machine GB |"
        );
        println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
        for p in std::iter::once(1).chain(MACHINES) {
            let t = model.time(TEXELS, p, bandwidth);
            println!(
                "| {p} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.1} |",
                t[0],
                t[1],
                t[2],
                t[3],
                t[4],
                t[5],
                t.iter().sum::<f64>(),
                model.memory(TEXELS, p) / 1e9
            );
        }
        println!();
    }
}

/// Time per stage and memory per machine against machines (stacked bars), for each bandwidth.
fn chart(path: &Path, model: &Model) -> Result<(), Box<dyn std::error::Error>> {
    font::register();
    let root = BitMapBackend::new(path, (1200, 420)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, 3));
    // One machine is in the printed table: its bar would flatten the others.
    let machines = MACHINES.to_vec();
    for ((name, bandwidth), panel) in BANDWIDTHS.iter().zip(panels.iter()) {
        let times: Vec<Vec<f64>> = machines
            .iter()
            .map(|&p| model.time(TEXELS, p, *bandwidth).to_vec())
            .collect();
        let caption = format!("time per machine, {name}");
        let y = "seconds (one thread each)";
        stacked(panel, &caption, y, &machines, &times, &STAGES)?;
    }
    let memory: Vec<Vec<f64>> = machines
        .iter()
        .map(|&p| {
            let all = model.memory(TEXELS, p) / 1e9;
            let shared = model.shared_bytes * TEXELS / 1e9;
            vec![shared, all - shared]
        })
        .collect();
    let parts = ["held by every machine", "its rows"];
    stacked(
        &panels[2],
        "memory per machine",
        "GB",
        &machines,
        &memory,
        &parts,
    )?;
    root.present()?;
    Ok(())
}

/// One panel of stacked bars: per machine count, `bars[i]` stacked in the order of `labels`.
fn stacked(
    panel: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    caption: &str,
    y_desc: &str,
    machines: &[usize],
    bars: &[Vec<f64>],
    labels: &[&str],
) -> Result<(), Box<dyn std::error::Error>> {
    let colors = [
        RGBColor(150, 150, 150),
        RGBColor(31, 119, 180),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
        RGBColor(255, 127, 14),
    ];
    let top = bars
        .iter()
        .map(|b| b.iter().sum::<f64>())
        .fold(0.0, f64::max)
        * 1.15;
    let mut chart = ChartBuilder::on(panel)
        .caption(caption, ("sans-serif", 18))
        .margin(8)
        .x_label_area_size(32)
        .y_label_area_size(56)
        .build_cartesian_2d(-0.5..machines.len() as f64 - 0.5, 0.0..top)?;
    chart
        .configure_mesh()
        .x_labels(machines.len())
        .x_label_formatter(&|v| {
            machines
                .get(v.round() as usize)
                .map_or(String::new(), |m| m.to_string())
        })
        .x_desc("machines")
        .y_desc(y_desc)
        .draw()?;
    for (k, (label, color)) in labels.iter().zip(colors).enumerate() {
        chart
            .draw_series(bars.iter().enumerate().map(|(i, b)| {
                let (x, below) = (i as f64, b[..k].iter().sum::<f64>());
                Rectangle::new(
                    [(x - 0.35, below), (x + 0.35, below + b[k])],
                    color.filled(),
                )
            }))?
            .label(*label)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], color.filled()));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}
