//! A bake over several processes, on the `timely` dataflow crate and its own TCP communication.
//!
//! Every process loads the same input with the same options and runs every stage of
//! [`super::prepare`] and the automatic choice; all are deterministic, so every process gets
//! the same atlas, texels and settings. What casts rays is divided (`Shared`):
//!
//! - every bake of a transport — the density pilot's pair, the ray pilots' pairs and the final
//!   bake — is sharded by rows: process `p` of `P` builds the Monte Carlo rows of texels
//!   `n·p/P .. n·(p+1)/P` (from the full scene) and keeps them. The first exchange gathers
//!   everyone's direct light; each Jacobi sweep then gathers its rows from the full radiosity
//!   vector and broadcasts its slice of the new `H` to every other process (an all-gather
//!   through a timely dataflow), so every process holds the whole vector after every sweep.
//!   The stopping rule is [`crate::solve`]'s, fed with the same sums in the same texel order,
//!   so every process stops after the same sweep with the single-process solution, bit for bit;
//! - the validity pass (the density pilot's and the final atlas's), the punctual light per
//!   texel and the planner's point samples compute their part of the items and gather the rest
//!   (`crate::shard`).
//!
//! What every process still does in full: loading, the junction split, the BVH, both atlases
//! and their texels, the whole-vector work of each sweep and the planner's arithmetic. Process
//! 0 then denoises, dilates, stitches seams and writes; the others write nothing.
//!
//! Failures: a process that fails with an error sends it to the others in its next exchange;
//! a process that dies closes its connections, which timely turns into a failure of its peers'
//! exchange (the message names the processes whose share did not come). Every process fails
//! then, before process 0 writes anything (output is staged, [`crate::output::Staging`]).
//! Connecting starts before loading and is waited for at the first exchange, at most
//! [`Cluster::connect_timeout`]. The TCP connections are set up here (`connect_sockets`) and
//! handed to timely: its own setup polls for peers once a second (a second of every bake) and
//! prints its progress to standard output.
//!
//! Only the stored Monte Carlo rows with the Jacobi solver ([`Technique::DEFAULT`]) are
//! distributed; the error map (which reads every row) is not.

use std::cell::RefCell;
use std::io::{self, Read, Write};
use std::net::{TcpListener, TcpStream, ToSocketAddrs};
use std::ops::Range;
use std::path::Path;
use std::rc::Rc;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use timely::communication::allocator::zero_copy::initialize::initialize_networking_from_sockets;
use timely::communication::allocator::{AllocatorBuilder, ProcessBuilder};
use timely::communication::initialize::Hooks;
use timely::dataflow::channels::pact::Pipeline;
use timely::dataflow::operators::generic::operator::Operator;
use timely::dataflow::operators::vec::Broadcast;
use timely::dataflow::operators::{Input, Probe};
use timely::dataflow::{InputHandle, ProbeHandle};
use timely::execute::execute_from;
use timely::worker::Worker;

use super::light::{Lit, Processes};
use super::{BakeReport, refuse_overwriting_input};
use crate::config::{BakeConfig, SolveParams, Technique, TransportParams};
use crate::lights::Emitters;
use crate::plan::error_map;
use crate::shard::{self, Shards};
use crate::solve::{self, Solution, Stopping, jacobi};
use crate::transport::{Surfaces, Transport, montecarlo, rows};
use crate::{Error, Progress, Result};

/// Where this process sits among the processes of a distributed bake.
#[derive(Clone, Debug)]
pub struct Cluster {
    /// `host:port` of every process, in process order (timely's hosts file); this process
    /// listens on its own.
    pub addresses: Vec<String>,
    /// This process's index in `addresses`.
    pub process: usize,
    /// How long to wait for every process to connect before giving up.
    pub connect_timeout: Duration,
}

/// What a distributed bake did: the bake itself on process 0, and the exchange's traffic.
#[derive(Clone, Debug)]
pub struct DistributedReport {
    /// The bake's report on process 0 (which wrote the files); `None` on the others.
    pub bake: Option<BakeReport>,
    /// Processes that took part.
    pub processes: usize,
    /// The texels whose rows this process built.
    pub rows: Range<usize>,
    /// Jacobi sweeps of the final bake.
    pub sweeps: usize,
    /// Payload bytes this process sent to the others in one sweep (its slice of `H` to each).
    pub bytes_per_sweep: u64,
    /// Payload bytes this process sent in all exchanges (pilots, samples and validity included).
    pub bytes_sent: u64,
    /// Wall seconds this process spent building its rows of the last transport (the final
    /// bake's, or the last pilot's when the pilot pair suffices).
    pub rows_seconds: f64,
    /// Wall seconds this process spent in that transport's sweeps.
    pub sweeps_seconds: f64,
    /// Of those, seconds spent in exchanges: the network, and waiting for slower processes.
    pub exchange_seconds: f64,
}

/// Bakes `input` into `out_dir` as process `cluster.process` of a distributed bake (see the
/// module doc): every process must be given the same input and `config`.
pub fn bake(
    input: &Path,
    out_dir: &Path,
    config: &BakeConfig,
    cluster: &Cluster,
    progress: &dyn Progress,
) -> Result<DistributedReport> {
    if cluster.process == 0 {
        refuse_overwriting_input(input, out_dir)?;
    }
    let config = distributable(config)?;
    let t = Instant::now();
    // Connecting runs while the scene loads and is prepared; the first exchange waits for it.
    let exchange = Exchange::connect(cluster)?;
    let (scene, source) = super::load(input, progress)?;
    if scene.triangles.is_empty() {
        // Nothing to share: process 0 writes the scene through as one process would.
        let bake = match cluster.process {
            0 => Some(super::pass_through(&source, input, out_dir, progress, t)?),
            _ => None,
        };
        return Ok(DistributedReport {
            bake,
            processes: cluster.addresses.len(),
            rows: 0..0,
            sweeps: 0,
            bytes_per_sweep: 0,
            bytes_sent: 0,
            rows_seconds: 0.0,
            sweeps_seconds: 0.0,
            exchange_seconds: 0.0,
        });
    }
    let shared = Shared(RefCell::new(exchange));
    let prepared = super::prepare_loaded(scene, source, input, &config, &shared, progress, t);
    let result = prepared.and_then(|p| bake_connected(p, out_dir, &config, &shared, progress));
    if let Err(e) = &result
        && !matches!(e, Error::Cluster(_))
    {
        // The others learn why in their next exchange, instead of waiting for a share.
        shared.0.borrow_mut().fail(e);
    }
    result
}

/// `config` for a distributed bake: the default technique, kept by the automatic choice.
fn distributable(config: &BakeConfig) -> Result<BakeConfig> {
    config.validate()?;
    if config.technique != Technique::DEFAULT {
        return Err(Error::Option(format!(
            "a distributed bake runs {} only, not {}",
            Technique::DEFAULT,
            config.technique
        )));
    }
    if config.output.error_map {
        return Err(Error::Option(
            "a distributed bake writes no error map (it reads every row, and each process holds \
             only its own)"
                .into(),
        ));
    }
    if config.output.keep_transport || config.output.layers.is_some() {
        return Err(Error::Option(
            "a distributed bake keeps no transport and writes no layers: its rows stay spread \
             over the processes (bake on one process for --keep-transport or --layers)"
                .into(),
        ));
    }
    let mut config = config.clone();
    if let Some(auto) = &mut config.auto {
        // Only stored rows are sharded: the memory check refuses a shard that does not fit
        // rather than switching to the matrix-free solver.
        auto.keep.method = true;
        auto.keep.solver = true;
    }
    Ok(config)
}

fn bake_connected(
    mut prepared: super::Prepared,
    out_dir: &Path,
    config: &BakeConfig,
    shared: &Shared,
    progress: &dyn Progress,
) -> Result<DistributedReport> {
    let input = prepared.source.path.clone();
    let lit = super::light(&mut prepared, shared, progress)?;
    let exchange = shared.0.borrow();
    let n = prepared.texels.len();
    let mut report = DistributedReport {
        bake: None,
        processes: exchange.processes,
        rows: exchange.rows(n),
        sweeps: lit.last.solution.history.len(),
        bytes_per_sweep: exchange.bytes_per_sweep(n),
        bytes_sent: exchange.bytes_sent,
        rows_seconds: exchange.rows_seconds,
        sweeps_seconds: exchange.sweeps_seconds,
        exchange_seconds: exchange.sweeps_waited.as_secs_f64(),
    };
    if exchange.process == 0 {
        drop(exchange);
        let baked = super::finish(prepared, lit, progress)?;
        report.bake = Some(super::write(baked, &input, out_dir, config, progress)?);
    }
    Ok(report)
}

/// The processes of a distributed bake, through their exchange.
struct Shared(RefCell<Exchange>);

impl Shards for Shared {
    fn count(&self) -> usize {
        self.0.borrow().processes
    }

    fn part(&self, n: usize) -> Range<usize> {
        self.0.borrow().rows(n)
    }

    fn gather(&self, mine: Vec<f32>, rays: u64, len: usize) -> Result<(Vec<f32>, u64)> {
        self.0.borrow_mut().all_gather(mine, rays, len)
    }
}

impl Processes for Shared {
    fn light(
        &self,
        surfaces: Surfaces,
        technique: Technique,
        params: &TransportParams,
        texel_rays: Option<&[u32]>,
        solve: &SolveParams,
        progress: &dyn Progress,
    ) -> Result<Lit> {
        if technique != Technique::DEFAULT {
            return Err(Error::Internal(format!(
                "a distributed bake runs {} only; the plan chose {technique}",
                Technique::DEFAULT,
            )));
        }
        let mut exchange = self.0.borrow_mut();
        solve_shared(surfaces, params, texel_rays, solve, progress, &mut exchange)
    }
}

/// A bake's rows of this process's texels, and the Jacobi solution of all of them (see the
/// module doc): the same as [`super::light::transport_and_solve`] with
/// [`Technique::DEFAULT`] on one machine.
fn solve_shared(
    surfaces: Surfaces,
    params: &TransportParams,
    texel_rays: Option<&[u32]>,
    solve: &SolveParams,
    progress: &dyn Progress,
    exchange: &mut Exchange,
) -> Result<Lit> {
    let texels = surfaces.texels;
    let n = texels.len();
    let mine = exchange.rows(n);
    let start = Instant::now();
    let emitters = Emitters::new(surfaces.scene, texels);
    let context = montecarlo::Context {
        surfaces,
        params,
        emitters: &emitters,
        texel_rays,
        // Direct light split by source is for a kept transport, which a distributed bake has
        // not (its rows stay spread over the processes).
        sources: None,
    };
    let rows = rows::build(
        mine.len(),
        montecarlo::CHUNK,
        "transport",
        progress,
        |range, out| {
            let mut scratch = montecarlo::RowScratch::new(params.gather_rays);
            for i in range {
                context.texel_row(mine.start + i, &mut scratch, out);
            }
        },
    )?;

    exchange.rows_seconds = start.elapsed().as_secs_f64();
    let (start, waited) = (Instant::now(), exchange.waited);

    // First exchange: direct light and sky fraction of every texel (and its punctual part,
    // which the planner's punctual sample reads, when a pilot run keeps it and the scene has
    // punctual lights), and the rays cast. Every process has the same lights and parameters,
    // so all send the same width.
    let width = if params.keep_punctual && !surfaces.scene.lights.is_empty() {
        7
    } else {
        4
    };
    let mut local: Vec<f32> = Vec::with_capacity(width * mine.len());
    for i in 0..mine.len() {
        let (d, e) = (rows.direct[i], rows.escape[i]);
        local.extend([d.x, d.y, d.z, e]);
        if width == 7 {
            local.extend(rows.punctual[i].to_array());
        }
    }
    let (all, rays) = exchange.all_gather(local, rows.rays, width * n)?;
    let direct: Vec<Vec3> = all.chunks_exact(width).map(Vec3::from_slice).collect();
    let escape: Vec<f32> = all.chunks_exact(width).map(|c| c[3]).collect();
    let punctual: Vec<Vec3> = match width {
        7 => all
            .chunks_exact(7)
            .map(|c| Vec3::from_slice(&c[4..]))
            .collect(),
        _ => Vec::new(),
    };

    let emitted = solve::row_emission(&rows, texels);
    let mut h = direct.clone();
    let mut solution = Solution::default();
    let mut stopping = Stopping::begin(
        ("jacobi", "sweeps"),
        solve,
        &mut solution.history,
        Instant::now(),
        progress,
    );
    while stopping.next()? {
        let radiosity = jacobi::radiosity(&h, &texels.albedo, &emitted);
        let local: Vec<f32> = (0..mine.len())
            .into_par_iter()
            .with_min_len(1024)
            .flat_map_iter(|i| jacobi::gathered(&rows, i, &radiosity).to_array())
            .collect();
        let (all, _) = exchange.all_gather(local, 0, 3 * n)?;
        let new: Vec<Vec3> = all.chunks_exact(3).map(Vec3::from_slice).collect();
        let sums = h.iter().zip(&new).map(|(o, n)| jacobi::row_change(*o, *n));
        let (change, total) = jacobi::sum_changes(sums);
        h = new;
        if stopping.sweep(change, total)? {
            solution.converged = true;
            break;
        }
    }
    stopping.end();
    exchange.sweeps_seconds = start.elapsed().as_secs_f64();
    exchange.sweeps_waited = exchange.waited - waited;
    // Each process measures its rows' texels and gathers the others'.
    let ray_variance = match params.ray_variance {
        true => {
            let mine = error_map::ray_variance(&rows, texels, &h, params.sky);
            exchange.all_gather(mine, 0, n)?.0
        }
        false => Vec::new(),
    };
    solution.irradiance = h;
    // The rows stay with the processes that built them; the rest is whole on every process.
    let transport = Transport {
        rows: crate::transport::Rows::Weights(crate::transport::WeightRows {
            row_start: vec![0; n + 1],
            col: Vec::new(),
            f: Vec::new(),
        }),
        escape,
        direct,
        rays,
        rows_carry_emission: rows.rows_carry_emission,
        direct_terms: Vec::new(),
        sources: Default::default(),
        punctual,
    };
    Ok(Lit {
        transport,
        solution,
        ray_variance,
    })
}

/// One process's part of an exchange round: its slice of a vector, or why it failed.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Share {
    from: usize,
    /// Counted from 1.
    round: usize,
    values: Vec<f32>,
    rays: u64,
    failure: Option<String>,
}

/// The all-gather of the distributed bake: a timely worker on its own thread (timely's closures
/// must own what they touch), fed shares over a channel and answering with each round's shares
/// of every process.
struct Exchange {
    process: usize,
    processes: usize,
    addresses: Vec<String>,
    outgoing: Sender<Share>,
    incoming: Receiver<Vec<Share>>,
    /// Per process, the rounds whose share has arrived (which process was lost, when a round
    /// fails).
    arrived: Arc<Mutex<Vec<usize>>>,
    round: usize,
    bytes_sent: u64,
    waited: Duration,
    /// The last transport's: seconds building rows, in sweeps, and waiting in those sweeps'
    /// exchanges.
    rows_seconds: f64,
    sweeps_seconds: f64,
    sweeps_waited: Duration,
    /// Until every process has connected: the signal that they have, and when to give up.
    connecting: Option<(Receiver<()>, Instant)>,
    connect_timeout: Duration,
    /// Joined when the exchange ends (a clean shutdown sends what is in flight); left running
    /// when connecting timed out or a process was lost.
    timely: Option<JoinHandle<std::result::Result<(), String>>>,
}

impl Exchange {
    /// Starts timely's communication; the first round waits until every process is connected.
    fn connect(cluster: &Cluster) -> Result<Exchange> {
        let processes = cluster.addresses.len();
        if cluster.process >= processes {
            return Err(Error::Option(format!(
                "process {} of a list of {processes}",
                cluster.process
            )));
        }
        let (outgoing, worker_in) = mpsc::channel();
        let (worker_out, incoming) = mpsc::channel();
        let (ready, connected) = mpsc::channel();
        let arrived = Arc::new(Mutex::new(vec![0; processes]));
        let deadline = Instant::now() + cluster.connect_timeout;
        let (process, addresses) = (cluster.process, cluster.addresses.clone());
        // One worker per process: timely's Fn closure takes the channels once.
        let ends = Mutex::new(Some((worker_in, worker_out, ready, arrived.clone())));
        let timely = std::thread::Builder::new()
            .name("timely".into())
            .spawn(move || {
                // A second past the deadline: the bake reports the timeout itself, and this
                // thread then ends rather than retrying for ever.
                let give_up = deadline + Duration::from_secs(1);
                let sockets = connect_sockets(&addresses, process, give_up)
                    .map_err(|e| format!("connecting: {e}"))?;
                let hooks = Hooks::default();
                let allocators =
                    ProcessBuilder::new_typed_vector(1, hooks.refill.clone(), hooks.spill.clone());
                let (builders, guard) =
                    initialize_networking_from_sockets(allocators, sockets, process, 1, hooks)
                        .map_err(|e| format!("starting timely's network threads: {e}"))?;
                let builders = builders.into_iter().map(AllocatorBuilder::Tcp).collect();
                let config = timely::WorkerConfig::default();
                let guards = execute_from(builders, Box::new(guard), config, move |worker| {
                    let ends = ends.lock().unwrap().take();
                    let (outgoing, incoming, ready, arrived) =
                        ends.expect("one worker per process");
                    serve(worker, outgoing, incoming, ready, arrived);
                })?;
                match guards.join().into_iter().find_map(|r| r.err()) {
                    Some(e) => Err(e),
                    None => Ok(()),
                }
            })
            .map_err(|e| Error::Cluster(format!("cannot start timely: {e}")))?;
        Ok(Exchange {
            process: cluster.process,
            processes,
            addresses: cluster.addresses.clone(),
            outgoing,
            incoming,
            arrived,
            round: 0,
            bytes_sent: 0,
            waited: Duration::ZERO,
            rows_seconds: 0.0,
            sweeps_seconds: 0.0,
            sweeps_waited: Duration::ZERO,
            connecting: Some((connected, deadline)),
            connect_timeout: cluster.connect_timeout,
            timely: Some(timely),
        })
    }

    /// Waits, until the connect timeout's deadline, for every process to connect.
    fn connected(&mut self) -> Result<()> {
        let Some((connected, deadline)) = self.connecting.take() else {
            return Ok(());
        };
        let start = Instant::now();
        let outcome = connected.recv_timeout(deadline.saturating_duration_since(start));
        self.waited += start.elapsed();
        match outcome {
            Ok(()) => Ok(()),
            Err(RecvTimeoutError::Timeout) => {
                self.timely = None; // connecting until a second past the deadline; left behind
                Err(Error::Cluster(format!(
                    "process {}: not every process connected within {:.0} s; is each of {} \
                     running with the same list and reachable?",
                    self.process,
                    self.connect_timeout.as_secs_f64(),
                    self.others()
                )))
            }
            Err(RecvTimeoutError::Disconnected) => {
                let why = self.join();
                Err(Error::Cluster(format!(
                    "process {} could not start its communication: {why}",
                    self.process,
                )))
            }
        }
    }

    /// The other processes, as `k (host:port)`.
    fn others(&self) -> String {
        let others: Vec<String> = (0..self.processes)
            .filter(|&p| p != self.process)
            .map(|p| format!("process {p} ({})", self.addresses[p]))
            .collect();
        others.join(", ")
    }

    /// This process's part of `n` texels (or other items).
    fn rows(&self, n: usize) -> Range<usize> {
        shard::part_of(self.process, self.processes, n)
    }

    fn bytes_per_sweep(&self, n: usize) -> u64 {
        (self.processes as u64 - 1) * (self.rows(n).len() * 3 * size_of::<f32>()) as u64
    }

    /// Sends `values` (this process's slice) and `rays` to every process and returns the
    /// concatenated slices of all processes, `len` values, and their summed rays.
    fn all_gather(&mut self, values: Vec<f32>, rays: u64, len: usize) -> Result<(Vec<f32>, u64)> {
        self.bytes_sent += (self.processes as u64 - 1) * (values.len() * size_of::<f32>()) as u64;
        let share = Share {
            from: self.process,
            round: self.round + 1,
            values,
            rays,
            failure: None,
        };
        let shares = self.round(share)?;
        let mut all = Vec::with_capacity(len);
        let mut rays = 0;
        for share in shares {
            if let Some(failure) = share.failure {
                return Err(Error::Cluster(format!(
                    "process {} failed: {failure}",
                    share.from
                )));
            }
            all.extend_from_slice(&share.values);
            rays += share.rays;
        }
        if all.len() != len {
            return Err(Error::Cluster(format!(
                "the processes disagree on the texels ({} values gathered, {len} expected): \
                 is every one baking the same input with the same options?",
                all.len()
            )));
        }
        Ok((all, rays))
    }

    /// Tells the other processes that this one failed with `error` (they are waiting for its
    /// share); best effort, as the process is failing anyway.
    fn fail(&mut self, error: &Error) {
        let share = Share {
            from: self.process,
            round: self.round + 1,
            values: Vec::new(),
            rays: 0,
            failure: Some(error.with_causes()),
        };
        let _ = self.round(share);
    }

    /// One round: every process's share, in process order.
    fn round(&mut self, share: Share) -> Result<Vec<Share>> {
        self.connected()?;
        self.round += 1;
        let lost = |exchange: &mut Exchange| {
            // Not joined: timely's threads end when the other processes close their
            // connections, and a hung one might not.
            exchange.timely = None;
            let missing: Vec<String> = (exchange.arrived.lock().unwrap().iter().enumerate())
                .filter(|&(p, &rounds)| rounds < exchange.round && p != exchange.process)
                .map(|(p, _)| format!("{p} ({})", exchange.addresses[p]))
                .collect();
            Error::Cluster(format!(
                "process {} lost contact with process {} in exchange {}: it died or its network \
                 failed",
                exchange.process,
                missing.join(", "),
                exchange.round,
            ))
        };
        if self.outgoing.send(share).is_err() {
            return Err(lost(self));
        }
        let start = Instant::now();
        let shares = self.incoming.recv();
        self.waited += start.elapsed();
        match shares {
            Ok(mut shares) => {
                shares.sort_by_key(|s| s.from);
                Ok(shares)
            }
            Err(_) => Err(lost(self)),
        }
    }

    /// Why timely's thread ended.
    fn join(&mut self) -> String {
        match self.timely.take().map(JoinHandle::join) {
            Some(Ok(Err(e))) => e,
            Some(Err(panic)) => panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "timely's communication failed".into()),
            _ => "timely's communication ended".into(),
        }
    }
}

impl Drop for Exchange {
    fn drop(&mut self) {
        // Closing the channel ends the worker, which shuts its connections down cleanly.
        let (closed, _) = mpsc::channel();
        self.outgoing = closed;
        // Still connecting (a bake that ended before its first exchange): timely's thread
        // waits for peers that may never come, so it is left behind.
        if let Some((connected, _)) = self.connecting.take()
            && connected.try_recv().is_err()
        {
            self.timely = None;
        }
        if let Some(timely) = self.timely.take() {
            let _ = timely.join();
        }
    }
}

/// TCP connections to every other process, in process order (`None` for this one), set up as
/// timely's own `create_sockets` does — each process connects to the lower ones and sends its
/// index, and accepts the higher ones — but polling every few milliseconds where timely sleeps
/// a second between attempts (a second of every bake), printing nothing, and giving up at
/// `give_up`.
fn connect_sockets(
    addresses: &[String],
    me: usize,
    give_up: Instant,
) -> io::Result<Vec<Option<TcpStream>>> {
    let listener = TcpListener::bind(&addresses[me])?;
    listener.set_nonblocking(true)?;
    let mut sockets: Vec<Option<TcpStream>> = addresses.iter().map(|_| None).collect();
    loop {
        for (p, address) in addresses.iter().enumerate().take(me) {
            if sockets[p].is_some() {
                continue;
            }
            // Not up yet (refused), or not resolvable yet: tried again on the next poll.
            let Some(addr) = address.to_socket_addrs().ok().and_then(|mut a| a.next()) else {
                continue;
            };
            if let Ok(mut stream) = TcpStream::connect_timeout(&addr, Duration::from_millis(500)) {
                stream.set_nodelay(true)?;
                stream.write_all(&(me as u64).to_be_bytes())?;
                sockets[p] = Some(stream);
            }
        }
        loop {
            match listener.accept() {
                Ok((mut stream, _)) => {
                    stream.set_nonblocking(false)?;
                    stream.set_nodelay(true)?;
                    let mut index = [0; 8];
                    stream.set_read_timeout(Some(Duration::from_secs(5)))?;
                    stream.read_exact(&mut index)?;
                    stream.set_read_timeout(None)?;
                    let p = u64::from_be_bytes(index) as usize;
                    if p > me && p < addresses.len() {
                        sockets[p] = Some(stream);
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                Err(e) => return Err(e),
            }
        }
        let missing = (0..addresses.len()).any(|p| p != me && sockets[p].is_none());
        if !missing {
            return Ok(sockets);
        }
        if Instant::now() > give_up {
            return Err(io::Error::new(
                io::ErrorKind::TimedOut,
                "not every process connected",
            ));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// The timely worker: a dataflow that broadcasts each round's shares, driven round by round
/// by the shares that come in on `outgoing`; each round's shares go back on `incoming`.
fn serve(
    worker: &mut Worker,
    outgoing: Receiver<Share>,
    incoming: Sender<Vec<Share>>,
    ready: Sender<()>,
    arrived: Arc<Mutex<Vec<usize>>>,
) {
    let mut input = InputHandle::new();
    let probe = ProbeHandle::new();
    let received = Rc::new(RefCell::new(Vec::new()));
    let sink = received.clone();
    let seen = arrived;
    worker.dataflow::<u64, _, _>(|scope| {
        scope
            .input_from(&mut input)
            .container::<Vec<Share>>()
            .broadcast()
            .unary::<timely::container::CapacityContainerBuilder<Vec<()>>, _, _, _>(
                Pipeline,
                "Gather",
                move |_, _| {
                    move |input, _| {
                        input.for_each(|_, shares| {
                            let mut seen = seen.lock().unwrap();
                            for share in shares.drain(..) {
                                seen[share.from] = share.round;
                                sink.borrow_mut().push(share);
                            }
                        })
                    }
                },
            )
            .probe_with(&probe);
    });
    let _ = ready.send(());
    while let Ok(share) = outgoing.recv() {
        let share_round = share.round;
        input.send(share);
        input.advance_to(input.time() + 1);
        while probe.less_than(input.time()) {
            worker.step_or_park(None);
        }
        // A faster process's share of the next round may be here already: it waits.
        let round = share_round;
        let (this, later) = received
            .take()
            .into_iter()
            .partition(|s: &Share| s.round == round);
        *received.borrow_mut() = later;
        if incoming.send(this).is_err() {
            break;
        }
    }
}
