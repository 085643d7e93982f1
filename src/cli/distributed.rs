//! `bake --processes N` (worker processes of this binary over loopback) and
//! `bake --hosts FILE --process I` (one process of a bake across machines); the bake itself is
//! [`lightbake::distributed`].

use std::ffi::OsString;
use std::net::TcpListener;
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::Duration;

use anyhow::{Context, Result, bail};
use lightbake::distributed::{Cluster, DistributedReport};

/// The distributed-bake flags of `bake`.
#[derive(clap::Args)]
pub struct Args {
    /// Bake with N worker processes of this program on this machine (timely over loopback):
    /// rows are split over them, and the output is the same bytes as one process's.
    #[arg(long, value_name = "N", conflicts_with_all = ["hosts", "peers", "process"])]
    processes: Option<usize>,
    /// Run one process of a bake across machines: FILE lists one host:port per process (the
    /// same file on every machine; each process listens on its own line's port).
    #[arg(
        long,
        value_name = "FILE",
        requires = "process",
        conflicts_with = "peers"
    )]
    hosts: Option<PathBuf>,
    /// This process's line in --hosts, from 0; process 0 writes the output.
    #[arg(long, value_name = "I")]
    process: Option<usize>,
    /// The processes' addresses, comma-separated: what --processes gives its workers.
    #[arg(long, hide = true, value_delimiter = ',', requires = "process")]
    peers: Option<Vec<String>>,
    /// Seconds a process waits for all the others to connect before the bake fails.
    #[arg(long, value_name = "SECONDS", default_value_t = 60.0)]
    connect_timeout: f64,
}

impl Args {
    /// Processes to spawn on this machine (`--processes`).
    pub fn processes(&self) -> Option<usize> {
        self.processes
    }

    /// This process's place in a distributed bake, if it is one.
    pub fn cluster(&self) -> Result<Option<Cluster>> {
        let addresses = match (&self.hosts, &self.peers) {
            (Some(file), _) => std::fs::read_to_string(file)
                .with_context(|| format!("cannot read the hosts file {}", file.display()))?
                .lines()
                .map(str::trim)
                .filter(|l| !l.is_empty())
                .map(String::from)
                .collect(),
            (None, Some(peers)) => peers.clone(),
            (None, None) => return Ok(None),
        };
        let process = self.process.unwrap_or(0);
        if process >= addresses.len() {
            bail!(
                "--process {process}: the hosts list has {} line(s)",
                addresses.len()
            );
        }
        Ok(Some(Cluster {
            addresses,
            process,
            connect_timeout: Duration::from_secs_f64(self.connect_timeout.max(0.0)),
        }))
    }
}

/// Silences the panics of timely's threads: a lost connection panics them by design (that is
/// how timely fails the other processes), and the bake's error names the lost process.
pub fn quiet_timely_panics() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let thread = std::thread::current();
        if !thread.name().is_some_and(|n| n.starts_with("timely")) {
            previous(info);
        }
    }));
}

/// The line a distributed process prints about its share of the work.
pub fn summary(report: &DistributedReport, process: usize) -> String {
    format!(
        "process {process} of {}: rows {}..{} built in {:.2}s, {} sweeps in {:.2}s ({:.2}s of it in \
         exchanges), {} bytes sent per sweep, {} in all",
        report.processes,
        report.rows.start,
        report.rows.end,
        report.rows_seconds,
        report.sweeps,
        report.sweeps_seconds,
        report.exchange_seconds,
        report.bytes_per_sweep,
        report.bytes_sent
    )
}

/// Runs this `bake` command as `n` worker processes on loopback and waits for them; when one
/// fails the others are stopped and the error names it. Process 0 prints and writes.
pub fn spawn(n: usize) -> Result<()> {
    if n == 0 {
        bail!("--processes must be at least 1");
    }
    let addresses = free_ports(n)?;
    let exe = std::env::current_exe().context("cannot find this program to start its workers")?;
    let args = without_processes(std::env::args_os().skip(1));
    let mut children: Vec<Child> = Vec::with_capacity(n);
    for process in 0..n {
        let mut command = Command::new(&exe);
        command
            .args(&args)
            .arg("--peers")
            .arg(addresses.join(","))
            .arg("--process")
            .arg(process.to_string());
        if process > 0 {
            // Quiet once: clap refuses a repeated `--quiet`.
            if !args.iter().any(|a| a == "--quiet" || a == "-q") {
                command.arg("--quiet");
            }
            command.stdout(Stdio::null());
        }
        match command.spawn() {
            Ok(child) => children.push(child),
            Err(e) => {
                stop(&mut children);
                return Err(e).context(format!("cannot start worker process {process}"));
            }
        }
    }
    supervise(&mut children)
}

/// Waits for every child; on the first failure stops the rest and names the failed one (one
/// killed by a signal before one that failed because it lost it).
fn supervise(children: &mut [Child]) -> Result<()> {
    let mut done = vec![None; children.len()];
    loop {
        for (child, status) in children.iter_mut().zip(&mut done) {
            if status.is_none() {
                *status = child
                    .try_wait()
                    .context("cannot wait for a worker process")?;
            }
        }
        let failed = |signalled: bool| {
            done.iter().enumerate().find_map(|(p, s)| match s {
                Some(s) if !s.success() && signal(s).is_some() == signalled => Some((p, *s)),
                _ => None,
            })
        };
        if let Some((process, status)) = failed(true).or_else(|| failed(false)) {
            stop(children);
            if process == 0 && status.code() == Some(crate::GATE_EXIT as i32) {
                return Err(crate::GateFailed("see process 0's message above".into()).into());
            }
            bail!(
                "worker process {process} (pid {}) {}; the bake is abandoned and nothing was written",
                children[process].id(),
                describe(&status)
            );
        }
        if done.iter().all(Option::is_some) {
            return Ok(());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Kills and reaps the children still running (only those this command started).
fn stop(children: &mut [Child]) {
    for child in children {
        if let Ok(None) = child.try_wait() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

fn signal(status: &ExitStatus) -> Option<i32> {
    #[cfg(unix)]
    {
        std::os::unix::process::ExitStatusExt::signal(status)
    }
    #[cfg(not(unix))]
    {
        let _ = status;
        None
    }
}

fn describe(status: &ExitStatus) -> String {
    match (signal(status), status.code()) {
        (Some(s), _) => format!("was killed by signal {s}"),
        (None, Some(code)) => format!("failed (exit code {code})"),
        (None, None) => "failed".into(),
    }
}

/// `n` loopback addresses with ports free a moment ago (bound together, then released for
/// timely to bind).
fn free_ports(n: usize) -> Result<Vec<String>> {
    let listeners = (0..n)
        .map(|_| TcpListener::bind("127.0.0.1:0"))
        .collect::<std::io::Result<Vec<_>>>()
        .context("cannot find free loopback ports")?;
    listeners
        .iter()
        .map(|l| Ok(l.local_addr()?.to_string()))
        .collect()
}

/// The command line without `--processes N` (or `--processes=N`).
fn without_processes(args: impl Iterator<Item = OsString>) -> Vec<OsString> {
    let mut out = Vec::new();
    let mut skip_value = false;
    for arg in args {
        if std::mem::take(&mut skip_value) {
            continue;
        }
        match arg.to_str() {
            Some("--processes") => skip_value = true,
            Some(a) if a.starts_with("--processes=") => {}
            _ => out.push(arg),
        }
    }
    out
}
