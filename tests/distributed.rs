//! Distributed bakes through the `lightbake` binary (issue 15): `--processes N` gives the same
//! bytes as one process for any N and thread count, and a process that dies or cannot be
//! reached fails the bake with a message naming it, leaving no output.

use std::net::TcpListener;
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use crate::util::{fixture, list_files, scratch};

fn lightbake(args: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_lightbake"));
    command.args(args);
    command
}

fn run(args: &[&str]) -> Output {
    lightbake(args).output().expect("run lightbake")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Every output file, by name, with its bytes.
fn outputs(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let files = list_files(dir);
    assert!(
        files.iter().any(|f| f.ends_with(".gltf")),
        "no glTF in {files:?}"
    );
    files
        .into_iter()
        .map(|f| (f.clone(), std::fs::read(dir.join(&f)).unwrap()))
        .collect()
}

/// `child`'s output once it ends, or a panic after `limit` (the test cannot hang).
fn finish_within(mut child: Child, limit: Duration) -> Output {
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            child.kill().unwrap();
            panic!("still running after {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// Loopback addresses with free ports, as a hosts file's lines.
fn free_addresses(n: usize) -> Vec<String> {
    let listeners: Vec<TcpListener> = (0..n)
        .map(|_| TcpListener::bind("127.0.0.1:0").unwrap())
        .collect();
    listeners
        .iter()
        .map(|l| l.local_addr().unwrap().to_string())
        .collect()
}

#[test]
fn processes_give_the_bytes_of_one_process_with_punctual_lights() {
    // The pilot runs' punctual light per texel travels in the first exchange (the planner's
    // punctual sample reads it): a wider exchange than the Cornell box's, which has none.
    let scene = fixture("spot_and_directional.gltf");
    let scene = scene.to_str().unwrap();
    let dir = scratch();
    let one = dir.path().join("one");
    let o = run(&[
        "bake",
        scene,
        "-o",
        one.to_str().unwrap(),
        "--quality",
        "draft",
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let expected = outputs(&one);
    for (processes, threads) in [("2", "1"), ("3", "2")] {
        let out = dir.path().join(format!("p{processes}t{threads}"));
        let o = run(&[
            "bake",
            scene,
            "-o",
            out.to_str().unwrap(),
            "--quality",
            "draft",
            "--processes",
            processes,
            "--threads",
            threads,
        ]);
        assert!(o.status.success(), "{}", text(&o.stderr));
        assert!(
            outputs(&out) == expected,
            "{processes} processes × {threads} threads: the output differs from one process's"
        );
    }
}

/// Bakes `scene` with `options` on one process and on two (one thread each), checks that both
/// write the same bytes and that the one process's output (`--explain` and summary) contains
/// `shows`, the path this case is about.
fn two_processes_write_one_process_bytes(scene: &str, options: &[&str], shows: &str) {
    let scene = fixture(scene);
    let dir = scratch();
    let bake = |out: &Path, more: &[&str]| {
        let out = out.to_str().unwrap();
        let args = [&["bake", scene.to_str().unwrap(), "-o", out], options, more].concat();
        let o = run(&args);
        assert!(o.status.success(), "{}", text(&o.stderr));
        text(&o.stdout) + &text(&o.stderr)
    };
    let one = dir.path().join("one");
    let said = bake(&one, &["--explain"]);
    assert!(
        said.contains(shows),
        "this bake no longer shows {shows:?} (pick one that does): {said}"
    );
    let two = dir.path().join("two");
    bake(&two, &["--processes", "2", "--threads", "1"]);
    assert!(
        outputs(&two) == outputs(&one),
        "2 processes: the output differs from one process's"
    );
}

#[test]
fn processes_give_the_bytes_of_one_process_when_the_atlas_is_laid_out_again() {
    // The lamp room at `draft` with seed 2: the laid-out atlas's own sample finds the density
    // pilot's choice short, and every process lays the atlas out again alike.
    let options = ["--quality", "draft", "--seed", "2"];
    two_processes_write_one_process_bytes("lamp_room.gltf", &options, "atlas again");
}

#[test]
fn processes_give_the_bytes_of_one_process_when_rays_follow_their_spread() {
    // The Cornell box for a 1.5% target: a second pilot pair (64 rays a run) and one more bake,
    // whose rays per texel follow what the pair's rays returned (`plan::spread_rays`): each
    // process measures its rows' texels and gathers the others'.
    let options = ["--quality", "draft", "--target-error", "0.015"];
    two_processes_write_one_process_bytes("cornell_box.gltf", &options, "rays where they disagree");
}

#[test]
fn processes_give_the_bytes_of_one_process() {
    let scene = fixture("cornell_box.gltf");
    let scene = scene.to_str().unwrap();
    // With the automatic choice (its pilot bakes, validity passes and samples sharded too)
    // and without it (only the final bake and the validity pass).
    let settings: [&[&str]; 2] = [
        &["--quality", "draft"],
        &["--quality", "draft", "--no-auto", "--rays", "48"],
    ];
    for options in settings {
        let dir = scratch();
        let one = dir.path().join("one");
        let args = [&["bake", scene, "-o", one.to_str().unwrap()], options].concat();
        let o = run(&[&args[..], &["--threads", "1"]].concat());
        assert!(o.status.success(), "{}", text(&o.stderr));
        let expected = outputs(&one);
        for processes in ["1", "2", "3"] {
            for threads in ["1", "2"] {
                let out = dir.path().join(format!("p{processes}t{threads}"));
                let o = run(&[
                    &["bake", scene, "-o", out.to_str().unwrap()],
                    options,
                    &["--processes", processes, "--threads", threads],
                ]
                .concat());
                let case = format!("{options:?}, {processes} processes × {threads} threads");
                assert!(o.status.success(), "{case}: {}", text(&o.stderr));
                let stdout = text(&o.stdout);
                assert!(
                    stdout.contains(&format!("process 0 of {processes}: rows 0..")),
                    "{case}: {stdout}"
                );
                assert!(
                    outputs(&out) == expected,
                    "{case}: the output differs from one process's"
                );
            }
        }
        // Without the pilot, the final bake was the sharded one: it swept.
        let stdout = text(
            &run(&[
                &args[..],
                &[
                    "--processes",
                    "2",
                    "-o",
                    dir.path().join("again").to_str().unwrap(),
                ],
            ]
            .concat())
            .stdout,
        );
        if options.contains(&"--no-auto") {
            assert!(!stdout.contains(" 0 sweeps"), "{stdout}");
        }
    }
}

/// A bake of a few seconds: long enough to kill a process in the middle of it.
const SLOW: [&str; 8] = [
    "--quality",
    "high",
    "--no-auto",
    "--rays",
    "2048",
    "--threads",
    "1",
    "--no-seams",
];

/// The pids of `parent`'s children (from /proc).
#[cfg(target_os = "linux")]
fn children_of(parent: u32) -> Vec<u32> {
    let mut pids = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(entry.path().join("stat")) else {
            continue;
        };
        // pid (comm) state ppid …: the command name may hold spaces, so read after its ')'.
        let after = &stat[stat.rfind(')').unwrap() + 2..];
        if after.split(' ').nth(1) == Some(&parent.to_string()) {
            pids.push(pid);
        }
    }
    pids
}

fn kill(pid: u32) {
    // SAFETY: kill(2) on a process this test started; no memory is involved.
    assert_eq!(unsafe { libc::kill(pid as libc::pid_t, libc::SIGKILL) }, 0);
}

#[cfg(target_os = "linux")]
#[test]
fn a_killed_worker_fails_the_bake_and_writes_nothing() {
    let dir = scratch();
    let out = dir.path().join("out");
    let scene = fixture("cornell_box.gltf");
    let parent = lightbake(
        &[
            &["bake", scene.to_str().unwrap(), "-o", out.to_str().unwrap()],
            &SLOW[..],
            &["--processes", "2"],
        ]
        .concat(),
    )
    .stdout(Stdio::null())
    .stderr(Stdio::piped())
    .spawn()
    .unwrap();
    let start = Instant::now();
    let workers = loop {
        let workers = children_of(parent.id());
        if workers.len() == 2 {
            break workers;
        }
        assert!(start.elapsed() < Duration::from_secs(10), "no workers");
        std::thread::sleep(Duration::from_millis(20));
    };
    std::thread::sleep(Duration::from_millis(1500));
    let victim = *workers
        .iter()
        .find(|pid| {
            let command = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
            let args: Vec<&[u8]> = command.split(|&b| b == 0).collect();
            args.windows(2).any(|w| w == [&b"--process"[..], &b"1"[..]])
        })
        .expect("process 1 among the workers");
    kill(victim);
    let o = finish_within(parent, Duration::from_secs(60));
    let stderr = text(&o.stderr);
    assert!(!o.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "worker process 1 (pid {victim}) was killed by signal 9"
        )),
        "{stderr}"
    );
    assert!(
        list_files(dir.path()).is_empty(),
        "{:?}",
        list_files(dir.path())
    );
}

/// Two processes of a hosts file, started by hand; process 1 is killed mid-bake: process 0
/// fails naming it, and writes nothing.
#[test]
fn a_lost_host_is_named() {
    let dir = scratch();
    let hosts = dir.path().join("hosts");
    std::fs::write(&hosts, free_addresses(2).join("\n")).unwrap();
    let out = dir.path().join("out");
    let scene = fixture("cornell_box.gltf");
    let start = |process: &str| {
        lightbake(
            &[
                &["bake", scene.to_str().unwrap(), "-o", out.to_str().unwrap()],
                &SLOW[..],
                &["--hosts", hosts.to_str().unwrap(), "--process", process],
            ]
            .concat(),
        )
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
    };
    let first = start("0");
    let mut second = start("1");
    std::thread::sleep(Duration::from_millis(2000));
    assert!(second.try_wait().unwrap().is_none(), "make the bake longer");
    second.kill().unwrap();
    second.wait().unwrap();
    let o = finish_within(first, Duration::from_secs(60));
    let stderr = text(&o.stderr);
    assert!(!o.status.success(), "{stderr}");
    assert!(
        stderr.contains("process 0 lost contact with process 1 (127.0.0.1:"),
        "{stderr}"
    );
    assert!(
        !out.exists() || list_files(&out).is_empty(),
        "{:?}",
        list_files(&out)
    );
}

/// A hosts file whose other process never starts: the bake gives up after --connect-timeout.
#[test]
fn an_unreachable_host_fails_after_the_timeout() {
    let dir = scratch();
    let hosts = dir.path().join("hosts");
    let addresses = free_addresses(2);
    std::fs::write(&hosts, addresses.join("\n")).unwrap();
    let out = dir.path().join("out");
    let scene = fixture("cornell_box.gltf");
    for process in ["0", "1"] {
        let child = lightbake(&[
            "bake",
            scene.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--quality",
            "draft",
            "--hosts",
            hosts.to_str().unwrap(),
            "--process",
            process,
            "--connect-timeout",
            "2",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
        let o = finish_within(child, Duration::from_secs(30));
        let stderr = text(&o.stderr);
        assert!(!o.status.success(), "{stderr}");
        let other = if process == "0" { 1 } else { 0 };
        assert!(
            stderr.contains("not every process connected within 2 s")
                && stderr.contains(&format!("process {other} ({})", addresses[other])),
            "process {process}: {stderr}"
        );
        assert!(
            !out.exists(),
            "process {process} wrote {:?}",
            list_files(&out)
        );
    }
}

/// `--max-memory` is checked per process: each process builds only its share of the final
/// rows, so a limit that refuses the bake on one process admits it on two, and two processes
/// still refuse a limit below their share. (Estimates are computed, not measured: with the rows
/// stored as ray counts, which the planner picks under these limits, one process needs 12.0 MiB
/// and each of two 10.6 MiB at most.)
#[test]
fn the_memory_limit_is_checked_per_process() {
    let scene = fixture("cornell_box.gltf");
    let scene = scene.to_str().unwrap();
    let bake = |dir: &Path, limit: &str, processes: &str| {
        let out = dir.join(format!("{limit}_{processes}"));
        // `--quiet` too: the spawned workers must not be given it twice.
        let options = [
            "--quality",
            "draft",
            "--no-auto",
            "--rays",
            "2048",
            "--quiet",
        ];
        let args = [
            "bake",
            scene,
            "-o",
            out.to_str().unwrap(),
            "--max-memory",
            limit,
        ];
        let o = run(&[&args[..], &options, &["--processes", processes]].concat());
        (o, out)
    };
    let dir = scratch();
    let (one, out) = bake(dir.path(), "11M", "1");
    let err = text(&one.stderr);
    assert!(!one.status.success(), "one process fit in 11 MiB: {err}");
    assert!(err.contains("above the memory limit 11.0 MiB"), "{err}");
    assert!(!err.contains("per process"), "{err}");
    assert!(!out.exists());
    let (two, out) = bake(dir.path(), "11M", "2");
    assert!(two.status.success(), "{}", text(&two.stderr));
    outputs(&out);
    let (tight, out) = bake(dir.path(), "9M", "2");
    let err = text(&tight.stderr);
    assert!(!tight.status.success(), "two processes fit in 9 MiB: {err}");
    assert!(err.contains("per process of 2"), "{err}");
    assert!(!out.exists());
}

/// A scene with no triangles is written through by process 0, as one process writes it.
#[test]
fn a_scene_with_nothing_to_bake_is_written_through() {
    let text_of = std::fs::read_to_string(fixture("cornell_box.gltf")).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text_of).unwrap();
    for mesh in json["meshes"].as_array_mut().unwrap() {
        for primitive in mesh["primitives"].as_array_mut().unwrap() {
            primitive["mode"] = serde_json::json!(0);
        }
    }
    let dir = scratch();
    let input = dir.path().join("points.gltf");
    std::fs::write(&input, json.to_string()).unwrap();
    let input = input.to_str().unwrap();
    let one = dir.path().join("one");
    let o = run(&["bake", input, "-o", one.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let expected = outputs(&one);
    let two = dir.path().join("two");
    let o = run(&[
        "bake",
        input,
        "-o",
        two.to_str().unwrap(),
        "--processes",
        "2",
    ]);
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("nothing to bake"), "{err}");
    assert_eq!(outputs(&two), expected);
}

/// A kept transport or layers need every row in one process: refused before any work, with the
/// reason, and nothing written.
#[test]
fn a_distributed_bake_refuses_to_keep_its_transport() {
    let scene = fixture("cornell_box.gltf");
    let dir = scratch();
    for option in ["--keep-transport", "--layers"] {
        let out = dir.path().join(option.trim_start_matches('-'));
        let o = run(&[
            "bake",
            scene.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--quality",
            "draft",
            "--processes",
            "2",
            "--quiet",
            option,
        ]);
        let err = text(&o.stderr);
        assert!(!o.status.success(), "{option} was accepted: {err}");
        assert!(
            err.contains("keeps no transport and writes no layers"),
            "{err}"
        );
        assert!(!out.exists(), "{option}: {:?}", list_files(&out));
    }
}
