//! The Slurm path of `jsim sweep --emit-slurm`, against a real Slurm: this test starts its own `munged`,
//! `slurmctld` and `slurmd` on localhost (a generated one-node `slurm.conf` with the machine's CPUs,
//! proctrack/linuxproc and all state under a temporary directory; nothing system-wide is touched), submits
//! the quick sweep (2 points × 4 exposures) as a 3-task job array with the emitted `submit.sh`, cancels one
//! array task while it runs, checks that the merge job was dropped and that `jsim merge` names the missing
//! units, resubmits, and asserts that the merged result is identical (all but the timing columns) to the
//! single-process run, with every unit recorded exactly once.
//!
//! Needs Debian's `slurm-wlm` and `munge` (`apt-get install slurm-wlm munge`). Outside CI the test is
//! skipped (with a note) when they are not installed; when the `CI` environment variable is set it fails
//! instead, and it fails everywhere if the daemons do not come up, printing their logs.

use engine::studies::sweep::{self, Shard};
use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const TOOLS: [&str; 8] = [
    "munged",
    "slurmctld",
    "slurmd",
    "sbatch",
    "squeue",
    "scontrol",
    "scancel",
    "sinfo",
];
mod support;
use support::{SMALL_SEQUENCE, build_jsim_mpi, in_ci, max_relative, numbers};

/// One private cluster at a time (the tests' daemons would share the machine's CPUs and its node name).
static ONE_CLUSTER: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn find_tool(name: &str) -> Option<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).collect())
        .unwrap_or_default();
    for d in [
        "/usr/sbin",
        "/usr/local/sbin",
        "/sbin",
        "/usr/bin",
        "/usr/local/bin",
    ] {
        dirs.push(PathBuf::from(d));
    }
    dirs.into_iter().map(|d| d.join(name)).find(|p| p.is_file())
}

fn output(cmd: &mut Command) -> (bool, String, String) {
    match cmd.output() {
        Ok(o) => (
            o.status.success(),
            String::from_utf8_lossy(&o.stdout).to_string(),
            String::from_utf8_lossy(&o.stderr).to_string(),
        ),
        Err(e) => (false, String::new(), e.to_string()),
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free TCP port")
}

/// A private one-node Slurm cluster; stopped (jobs cancelled, daemons terminated) on drop.
struct Cluster {
    dir: PathBuf,
    conf: PathBuf,
    tools: BTreeMap<&'static str, PathBuf>,
    daemons: Vec<(&'static str, Child)>,
    user: String,
    keep: bool,
}

impl Cluster {
    fn tool(&self, name: &str) -> Command {
        let mut c = Command::new(&self.tools[name]);
        c.env("SLURM_CONF", &self.conf);
        c
    }

    fn logs(&self) -> String {
        let mut s = String::new();
        for f in [
            "munged.log",
            "munged.out",
            "slurmctld.log",
            "slurmctld.out",
            "slurmd.log",
            "slurmd.out",
            "slurm.conf",
        ] {
            let p = self.dir.join(f);
            if let Ok(t) = std::fs::read_to_string(&p) {
                let tail: Vec<&str> = t.lines().rev().take(60).collect();
                s.push_str(&format!(
                    "----- {} (last {} lines) -----\n",
                    p.display(),
                    tail.len()
                ));
                for l in tail.into_iter().rev() {
                    s.push_str(l);
                    s.push('\n');
                }
            }
        }
        for (name, _) in &self.daemons {
            s.push_str(&format!("(daemon {name} was started)\n"));
        }
        s
    }

    fn fail(&mut self, what: &str) -> ! {
        self.keep = true;
        panic!(
            "{what}\nthe cluster's files are kept in {}\n{}",
            self.dir.display(),
            self.logs()
        );
    }

    /// Start munged, slurmctld and slurmd. `Err` carries a description (the daemons' logs included).
    fn start(tools: BTreeMap<&'static str, PathBuf>, tag: &str) -> Result<Cluster, String> {
        let dir = std::env::temp_dir().join(format!("jsim-slurm-{}-{tag}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
        let (_, user, _) = output(Command::new("id").arg("-un"));
        let user = user.trim().to_string();
        let mut c = Cluster {
            conf: dir.join("slurm.conf"),
            dir,
            tools,
            daemons: Vec::new(),
            user,
            keep: false,
        };
        private_directories_and_key(&c.dir)?;
        let socket = c.dir.join("munge/munge.socket");
        let d = c.dir.clone();
        c.spawn(
            "munged",
            &[
                "-F".into(),
                "-f".into(),
                format!("--key-file={}", d.join("munge-key/munge.key").display()),
                format!("--socket={}", socket.display()),
                format!("--pid-file={}", d.join("munged.pid").display()),
                format!("--log-file={}", d.join("munged.log").display()),
                format!("--seed-file={}", d.join("munge-key/munged.seed").display()),
            ],
        )?;
        c.wait_for("munged's socket", 15, |c| {
            c.check_alive()?;
            Ok(socket.exists())
        })?;

        let host = short_host_name();
        let node_hw = node_hardware(&c.tools["slurmd"]);
        let conf = slurm_conf(&host, &node_hw, &c.user, &socket, &d);
        std::fs::write(&c.conf, conf).map_err(|e| e.to_string())?;
        let conf_arg = c.conf.display().to_string();
        c.spawn(
            "slurmctld",
            &["-D".into(), "-i".into(), "-f".into(), conf_arg.clone()],
        )?;
        c.spawn(
            "slurmd",
            &[
                "-D".into(),
                "-N".into(),
                host.clone(),
                "-f".into(),
                conf_arg,
            ],
        )?;
        c.wait_for("the node to become idle", 60, |c| {
            c.check_alive()?;
            let (_, out, _) = output(c.tool("sinfo").args(["-h", "-N", "-o", "%T"]));
            Ok(out.trim() == "idle")
        })?;
        Ok(c)
    }

    fn spawn(&mut self, name: &'static str, args: &[String]) -> Result<(), String> {
        let out = File::create(self.dir.join(format!("{name}.out"))).map_err(|e| e.to_string())?;
        let err = out.try_clone().map_err(|e| e.to_string())?;
        let child = Command::new(&self.tools[name])
            .args(args)
            .env("SLURM_CONF", &self.conf)
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(err)
            .spawn()
            .map_err(|e| format!("cannot start {name}: {e}"))?;
        self.daemons.push((name, child));
        Ok(())
    }

    fn check_alive(&mut self) -> Result<(), String> {
        for (name, child) in &mut self.daemons {
            if let Ok(Some(status)) = child.try_wait() {
                return Err(format!("{name} exited ({status})"));
            }
        }
        Ok(())
    }

    fn wait_for(
        &mut self,
        what: &str,
        seconds: u64,
        mut ready: impl FnMut(&mut Cluster) -> Result<bool, String>,
    ) -> Result<(), String> {
        let t0 = Instant::now();
        loop {
            match ready(self) {
                Ok(true) => return Ok(()),
                Ok(false) => {}
                Err(e) => return Err(format!("waiting for {what}: {e}\n{}", self.logs())),
            }
            if t0.elapsed() > Duration::from_secs(seconds) {
                return Err(format!(
                    "timed out after {seconds} s waiting for {what}\n{}",
                    self.logs()
                ));
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// `JobState` of a job (`123`, `123_4`), from `scontrol`.
    fn job_state(&self, id: &str) -> String {
        let (_, out, _) = output(self.tool("scontrol").args(["-o", "show", "job", id]));
        out.split_whitespace()
            .find_map(|kv| kv.strip_prefix("JobState="))
            .unwrap_or("UNKNOWN")
            .to_string()
    }

    /// Whether any of the jobs (comma-separated ids) is still pending or running.
    fn queued(&mut self, ids: &str) -> bool {
        let (ok, out, err) = output(self.tool("squeue").args(["-h", "-o", "%i %T", "-j", ids]));
        if !ok {
            self.fail(&format!("squeue -j {ids} failed: {err}"));
        }
        !out.trim().is_empty()
    }

    fn wait_jobs_done(&mut self, ids: &str, seconds: u64) {
        let t0 = Instant::now();
        while self.queued(ids) {
            if t0.elapsed() > Duration::from_secs(seconds) {
                let (_, q, _) = output(self.tool("squeue").args(["-j", ids]));
                self.fail(&format!("jobs {ids} still queued after {seconds} s:\n{q}"));
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        if std::thread::panicking() && !self.keep {
            eprintln!("{}", self.logs());
            self.keep = true;
        }
        let _ = self.tool("scancel").args(["-u", &self.user]).output();
        // stop the daemons: SIGTERM (by pid), then SIGKILL whatever is left
        for (_, child) in self.daemons.iter_mut().rev() {
            let _ = Command::new("kill")
                .args(["-TERM", &child.id().to_string()])
                .output();
            let t0 = Instant::now();
            while t0.elapsed() < Duration::from_secs(10) {
                if let Ok(Some(_)) = child.try_wait() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = child.kill();
            let _ = child.wait();
        }
        if !self.keep {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

fn jsim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_jsim"))
}

fn run_ok(cmd: &mut Command, what: &str) -> String {
    let (ok, out, err) = output(cmd);
    assert!(ok, "{what} failed:\n{out}\n{err}");
    out
}

/// The private cluster, or None (with a note) where Slurm is not installed outside CI.
fn cluster(tag: &str) -> Option<Cluster> {
    let mut tools = BTreeMap::new();
    let mut missing = Vec::new();
    for t in TOOLS {
        match find_tool(t) {
            Some(p) => {
                tools.insert(t, p);
            }
            None => missing.push(t),
        }
    }
    if !missing.is_empty() {
        let msg = format!(
            "Slurm is not installed (missing {}): apt-get install slurm-wlm munge",
            missing.join(", ")
        );
        if in_ci() {
            panic!("CI is set and the Slurm test cannot run: {msg} (.ci/run installs them)");
        }
        eprintln!("skipping the Slurm test: {msg}");
        return None;
    }
    match Cluster::start(tools, tag) {
        Ok(c) => Some(c),
        Err(e) => panic!("the Slurm daemons did not start: {e}"),
    }
}

#[test]
fn slurm_array_resumes_after_a_cancelled_task_and_matches_one_process() {
    let _one = ONE_CLUSTER.lock().unwrap_or_else(|e| e.into_inner());
    let t_start = Instant::now();
    let Some(mut cluster) = cluster("sweep") else {
        return;
    };
    eprintln!(
        "slurm cluster up in {:.1} s ({})",
        t_start.elapsed().as_secs_f64(),
        cluster.dir.display()
    );

    let quick = Path::new(env!("CARGO_MANIFEST_DIR")).join("sweeps/quick_sweep.toml");
    let work = cluster.dir.join("work");
    let reference = work.join("reference");
    let out = work.join("slurm-run");

    // the single-process run of the same sweep
    run_ok(
        jsim()
            .arg("sweep")
            .arg("--config")
            .arg(&quick)
            .arg("--out")
            .arg(&reference),
        "reference sweep",
    );
    run_ok(jsim().arg("merge").arg(&reference), "reference merge");
    run_ok(jsim().arg("report").arg(&reference), "reference report");

    // emit the scripts and submit
    run_ok(
        jsim()
            .arg("sweep")
            .arg("--config")
            .arg(&quick)
            .arg("--out")
            .arg(&out)
            .args(["--emit-slurm", "--shards", "3", "--time", "00:10:00"]),
        "jsim sweep --emit-slurm",
    );
    let submit = out.join("slurm/submit.sh");
    let sub = |c: &Cluster| {
        let mut cmd = Command::new("bash");
        cmd.arg(&submit).env("SLURM_CONF", &c.conf);
        let o = run_ok(&mut cmd, "submit.sh");
        let read = |n: &str| {
            std::fs::read_to_string(out.join("slurm").join(n))
                .expect("job id file")
                .trim()
                .to_string()
        };
        (o, read("array.jobid"), read("merge.jobid"))
    };
    let (said, array, merge) = sub(&cluster);
    eprintln!("{said}");

    // cancel task 1 as soon as it has recorded its first unit (it has three)
    let rec = sweep::read_record(&out).expect("sweep.json");
    let shard1 = Shard::new(1, 3).expect("shard");
    let side1 = sweep::shard_paths(&out, shard1).1;
    let t0 = Instant::now();
    while !side1.exists() {
        if t0.elapsed() > Duration::from_secs(120) {
            cluster.fail("task 1 never recorded a unit");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let task1 = format!("{array}_1");
    run_ok(cluster.tool("scancel").arg(&task1), "scancel");
    cluster.wait_jobs_done(&format!("{array},{merge}"), 180);
    let state1 = cluster.job_state(&task1);
    if state1 != "CANCELLED" {
        cluster.fail(&format!("task {task1} ended {state1}, not CANCELLED"));
    }
    let partial = sweep::read_shard(&rec, &out, shard1).expect("shard 1");
    assert!(
        partial.units.len() < 3,
        "task 1 finished before the cancel landed ({} units): the test could not interrupt it",
        partial.units.len()
    );
    eprintln!(
        "cancelled {task1} after {} of its 3 units; merge job {merge}: {}",
        partial.units.len(),
        cluster.job_state(&merge)
    );
    // the merge job depended on every task succeeding: Slurm dropped it
    assert_eq!(cluster.job_state(&merge), "CANCELLED");
    assert!(!out.join("merged.csv").exists());
    // and merging by hand names what is missing
    let (ok, _, err) = output(jsim().arg("merge").arg(&out));
    assert!(!ok, "merge must fail with units missing");
    assert!(err.contains("units are missing"), "{err}");

    // resubmit: only the lost units are computed, then merge + report run
    let (said, array2, merge2) = sub(&cluster);
    eprintln!("{said}");
    cluster.wait_jobs_done(&format!("{array2},{merge2}"), 240);
    let st = cluster.job_state(&merge2);
    if st != "COMPLETED" {
        cluster.fail(&format!("merge job {merge2} ended {st}"));
    }
    let log = |task: &str| {
        std::fs::read_to_string(out.join(format!("slurm/logs/sweep-{array2}_{task}.out")))
            .unwrap_or_default()
    };
    assert!(log("0").contains("3 already done, 0 to do"), "{}", log("0"));
    assert!(log("2").contains("2 already done, 0 to do"), "{}", log("2"));
    assert!(
        log("1").contains(&format!(
            "{} already done, {} to do",
            partial.units.len(),
            3 - partial.units.len()
        )),
        "{}",
        log("1")
    );

    // identical to the single-process run, apart from the timing columns
    let merged = std::fs::read_to_string(out.join("merged.csv")).expect("merged.csv");
    let want = std::fs::read_to_string(reference.join("merged.csv")).expect("reference merged");
    assert_eq!(sweep::without_timing(&merged), sweep::without_timing(&want));
    assert_eq!(merged.lines().count(), 1 + 8 * 3);
    assert_eq!(
        std::fs::read(out.join("report.csv")).expect("report.csv"),
        std::fs::read(reference.join("report.csv")).expect("reference report")
    );
    // nothing lost, nothing duplicated: every unit in exactly one shard file
    let mut seen = BTreeMap::new();
    for s in sweep::list_shards(&out).expect("shards") {
        let f = sweep::read_shard(&rec, &out, s).expect("shard");
        assert!(f.intact, "{:?}", f.note);
        for u in f.units.keys() {
            *seen.entry(*u).or_insert(0) += 1;
        }
    }
    assert_eq!(
        seen.keys().copied().collect::<Vec<_>>(),
        (0..8).collect::<Vec<_>>()
    );
    assert!(seen.values().all(|&n| n == 1), "{seen:?}");
    eprintln!(
        "slurm test done in {:.1} s",
        t_start.elapsed().as_secs_f64()
    );
}

/// The whole chain on a real Slurm: a sequence's job array (`jsim sequence --emit-slurm`, 2 shards) and its
/// gathering, then the solution on 2 MPI ranks started by `srun` (`jsim solve --emit-slurm --ranks 2`),
/// submitted at once by the sequence's submit.sh with `afterok` dependencies; the solution agrees with one
/// process's `jsim solve` of the same catalogues to 10⁻⁹ relative.
#[test]
fn a_sequence_then_its_solution_on_two_mpi_ranks_under_slurm() {
    let _one = ONE_CLUSTER.lock().unwrap_or_else(|e| e.into_inner());
    let Some(mut cluster) = cluster("solve") else {
        return;
    };
    if support::mpirun_or_skip().is_none() {
        return;
    }
    let jsim_mpi = build_jsim_mpi();
    let work = cluster.dir.join("work");
    std::fs::create_dir_all(&work).expect("work");
    let spec = work.join("seq.toml");
    std::fs::write(
        &spec,
        "[sequence]\nstares_l = 2\nstares_b = 1\nexposures_per_stare = 2\nvisit_dither_px = 20.0\n",
    )
    .expect("spec");
    let seq = work.join("seq");
    let mut cmd = jsim();
    cmd.args(["sequence", "--countermeasure", "none", "--spec"])
        .arg(&spec);
    for s in SMALL_SEQUENCE {
        cmd.args(["--set", s]);
    }
    cmd.arg("--out").arg(&seq).args([
        "--emit-slurm",
        "--shards",
        "2",
        "--cpus-per-task",
        "1",
        "--time",
        "00:20:00",
    ]);
    run_ok(&mut cmd, "jsim sequence --emit-slurm");
    // a bad rank count is named and writes nothing
    let (ok, _, err) = output(
        jsim()
            .args(["solve", "--sequence"])
            .arg(&seq)
            .args(["--emit-slurm", "--ranks", "3", "--jsim-mpi"])
            .arg(&jsim_mpi),
    );
    assert!(!ok && err.contains("--ranks 3"), "{err}");
    assert!(!seq.join("slurm/solve.sbatch").exists());
    let by_slurm = work.join("solution-slurm");
    run_ok(
        jsim()
            .args(["solve", "--sequence"])
            .arg(&seq)
            .args([
                "--emit-slurm",
                "--ranks",
                "2",
                "--time",
                "00:20:00",
                "--jsim-mpi",
            ])
            .arg(&jsim_mpi)
            .arg("--out")
            .arg(&by_slurm),
        "jsim solve --emit-slurm",
    );
    let script = std::fs::read_to_string(seq.join("slurm/solve.sbatch")).expect("solve.sbatch");
    assert!(script.contains("#SBATCH --ntasks=2") && script.contains("srun --mpi=pmix"));
    let said = run_ok(
        Command::new("bash")
            .arg(seq.join("slurm/submit.sh"))
            .env("SLURM_CONF", &cluster.conf),
        "submit.sh",
    );
    eprintln!("{said}");
    let id = |what: &str| -> String {
        said.lines()
            .find_map(|l| {
                l.strip_prefix(&format!("submitted {what} job "))
                    .map(|r| r.split_whitespace().next().unwrap_or("").to_string())
            })
            .unwrap_or_else(|| panic!("no {what} job id in {said:?}"))
    };
    let solve = id("solve");
    let array = said
        .split_whitespace()
        .skip_while(|w| *w != "array")
        .nth(2)
        .unwrap_or_default()
        .to_string();
    cluster.wait_jobs_done(&format!("{array},{solve}"), 900);
    let state = cluster.job_state(&solve);
    let log = std::fs::read_to_string(seq.join(format!("slurm/logs/solve-{solve}.out")))
        .unwrap_or_default();
    if state != "COMPLETED" {
        cluster.fail(&format!("solve job {solve} ended {state}:\n{log}"));
    }
    assert!(log.contains("on 2 rank(s)"), "{log}");
    // one process, the same catalogues
    let one = work.join("solution-one");
    run_ok(
        jsim()
            .args(["solve", "--sequence"])
            .arg(&seq)
            .arg("--out")
            .arg(&one),
        "jsim solve",
    );
    for f in ["sources.csv", "attitudes.csv"] {
        let worst = max_relative(&numbers(&one.join(f)), &numbers(&by_slurm.join(f)));
        eprintln!(
            "{f}: largest relative difference {worst:e} (2 ranks under Slurm against one process)"
        );
        assert!(worst <= 1e-9, "{f}: {worst:e}");
    }
}

/// munged insists on private key and log directories and a socket directory everyone may enter; its key is
/// 1 KiB of /dev/urandom.
fn private_directories_and_key(dir: &Path) -> Result<(), String> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let perm =
            |p: &Path, m: u32| std::fs::set_permissions(p, std::fs::Permissions::from_mode(m));
        perm(dir, 0o711).map_err(|e| e.to_string())?;
        for (d, m) in [
            ("munge-key", 0o700),
            ("munge", 0o711),
            ("state", 0o700),
            ("spool", 0o755),
        ] {
            std::fs::create_dir_all(dir.join(d)).map_err(|e| e.to_string())?;
            perm(&dir.join(d), m).map_err(|e| e.to_string())?;
        }
        let mut key = vec![0u8; 1024];
        let mut f = File::open("/dev/urandom").map_err(|e| e.to_string())?;
        std::io::Read::read_exact(&mut f, &mut key).map_err(|e| e.to_string())?;
        let kp = dir.join("munge-key/munge.key");
        std::fs::write(&kp, key).map_err(|e| e.to_string())?;
        perm(&kp, 0o600).map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// Our host name, short, as slurmd names its node.
fn short_host_name() -> String {
    let (_, host, _) = output(Command::new("hostname").arg("-s"));
    let host = host.trim().to_string();
    if host.is_empty() {
        std::fs::read_to_string("/proc/sys/kernel/hostname")
            .unwrap_or_else(|_| "localhost".into())
            .trim()
            .split('.')
            .next()
            .unwrap_or("localhost")
            .to_string()
    } else {
        host
    }
}

/// The node as slurmd sees it (CPUs, sockets, cores, threads), as slurm.conf's node line takes it.
fn node_hardware(slurmd: &Path) -> String {
    let (_, hw, _) = output(Command::new(slurmd).arg("-C"));
    let node_hw: Vec<String> = hw
        .lines()
        .next()
        .unwrap_or("")
        .split_whitespace()
        .filter(|kv| {
            [
                "CPUs=",
                "Boards=",
                "SocketsPerBoard=",
                "CoresPerSocket=",
                "ThreadsPerCore=",
            ]
            .iter()
            .any(|k| kv.starts_with(k))
        })
        .map(String::from)
        .collect();
    if node_hw.iter().any(|kv| kv.starts_with("CPUs=")) {
        node_hw.join(" ")
    } else {
        format!(
            "CPUs={}",
            std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1)
        )
    }
}

/// slurm.conf for one node on this host, its daemons' files under `d`, its ports free ones.
fn slurm_conf(host: &str, node_hw: &str, user: &str, socket: &Path, d: &Path) -> String {
    format!(
        "# generated by engine/tests/slurm.rs
ClusterName=jsimtest
SlurmctldHost={host}(127.0.0.1)
SlurmUser={user}
SlurmdUser={user}
SlurmctldPort={p1}
SlurmdPort={p2}
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={socket}
StateSaveLocation={d}/state
SlurmdSpoolDir={d}/spool
SlurmctldPidFile={d}/slurmctld.pid
SlurmdPidFile={d}/slurmd.pid
SlurmctldLogFile={d}/slurmctld.log
SlurmdLogFile={d}/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
SwitchType=switch/none
MailProg=/bin/true
ReturnToService=2
MinJobAge=600
KillWait=5
NodeName={host} NodeAddr=127.0.0.1 {node_hw} State=UNKNOWN
PartitionName=debug Nodes={host} Default=YES MaxTime=INFINITE State=UP
",
        p1 = free_port(),
        p2 = free_port(),
        socket = socket.display(),
        d = d.display(),
    )
}
