//! Where the machine's CPU goes, read from Linux's `/proc`: the
//! acquisition's own threads, one thread of the view, and the other
//! processes that keep the cores busy, so that the page can say why a
//! reconstruction gets no CPU and who has it. Elsewhere every reading is
//! `None` and the page says less.

/// Threads of the view are named with this prefix; they are not the
/// acquisition's.
pub const VIEW_THREAD_PREFIX: &str = "live-";

/// Clock ticks per second of `/proc`'s CPU times.
#[cfg(target_os = "linux")]
fn ticks_per_s() -> Option<f64> {
    // SAFETY: sysconf has no preconditions.
    let tick = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    (tick > 0).then_some(tick as f64)
}

/// The fields of a `/proc/.../stat` line after the command's closing
/// parenthesis (field 3 first), and the command.
#[cfg(target_os = "linux")]
fn stat_fields(stat: &str) -> Option<(String, Vec<&str>)> {
    let open = stat.find('(')?;
    let (head, rest) = stat.rsplit_once(')')?;
    let comm = head.get(open + 1..)?.to_string();
    Some((comm, rest.split_whitespace().collect()))
}

/// Field `n` (numbered as `proc(5)` numbers them) of `fields`.
#[cfg(target_os = "linux")]
fn field(fields: &[&str], n: usize) -> Option<u64> {
    fields.get(n - 3).and_then(|v| v.parse().ok())
}

/// CPU seconds spent so far by this process's threads that are the
/// acquisition's: neither in the idle class nor named as the view's;
/// `None` where that cannot be read.
pub fn acquisition_cpu_s() -> Option<f64> {
    #[cfg(target_os = "linux")]
    {
        let tick = ticks_per_s()?;
        let mut ticks = 0u64;
        for task in std::fs::read_dir("/proc/self/task").ok()?.flatten() {
            let Ok(stat) = std::fs::read_to_string(task.path().join("stat")) else {
                continue; // the thread ended
            };
            let Some((comm, f)) = stat_fields(&stat) else {
                continue;
            };
            // utime 14, stime 15, policy 41.
            if field(&f, 41) == Some(libc::SCHED_IDLE as u64)
                || comm.starts_with(VIEW_THREAD_PREFIX)
            {
                continue;
            }
            ticks += field(&f, 14).unwrap_or(0) + field(&f, 15).unwrap_or(0);
        }
        Some(ticks as f64 / tick)
    }
    #[cfg(not(target_os = "linux"))]
    None
}

/// CPU seconds spent so far by this process's threads whose name starts
/// with `prefix` (those alive now: an ended thread takes its time along).
pub fn threads_cpu_s(prefix: &str) -> Option<f64> {
    #[cfg(target_os = "linux")]
    {
        let tick = ticks_per_s()?;
        let mut ticks = 0u64;
        for task in std::fs::read_dir("/proc/self/task").ok()?.flatten() {
            let Ok(stat) = std::fs::read_to_string(task.path().join("stat")) else {
                continue;
            };
            let Some((comm, f)) = stat_fields(&stat) else {
                continue;
            };
            if comm.starts_with(prefix) {
                ticks += field(&f, 14).unwrap_or(0) + field(&f, 15).unwrap_or(0);
            }
        }
        Some(ticks as f64 / tick)
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = prefix;
        None
    }
}

/// One process's CPU seconds so far.
#[derive(Debug, Clone, PartialEq)]
struct ProcessTime {
    pid: u32,
    name: String,
    cpu_s: f64,
}

/// Every process's CPU seconds so far (the ones that can be read).
fn processes() -> Vec<ProcessTime> {
    #[cfg(target_os = "linux")]
    {
        let Some(tick) = ticks_per_s() else {
            return Vec::new();
        };
        let Ok(dir) = std::fs::read_dir("/proc") else {
            return Vec::new();
        };
        dir.flatten()
            .filter_map(|e| {
                let pid: u32 = e.file_name().to_str()?.parse().ok()?;
                let stat = std::fs::read_to_string(e.path().join("stat")).ok()?;
                let (name, f) = stat_fields(&stat)?;
                let ticks = field(&f, 14)? + field(&f, 15)?;
                Some(ProcessTime {
                    pid,
                    name,
                    cpu_s: ticks as f64 / tick,
                })
            })
            .collect()
    }
    #[cfg(not(target_os = "linux"))]
    Vec::new()
}

/// Another process and the cores it kept busy.
#[derive(Debug, Clone, PartialEq)]
pub struct Busy {
    /// Its id.
    pub pid: u32,
    /// Its command name.
    pub name: String,
    /// Cores it kept busy since the previous look.
    pub cores: f64,
}

/// The other processes' use of the machine, from one look to the next.
#[derive(Debug, Default)]
pub struct OtherProcesses {
    last: Option<(std::time::Instant, Vec<ProcessTime>)>,
}

impl OtherProcesses {
    /// A first look (the next call measures from here).
    pub fn new() -> Self {
        let mut p = Self::default();
        p.look();
        p
    }

    /// The other processes that kept at least a tenth of a core busy since
    /// the previous look, busiest first (empty the first time, or where
    /// `/proc` cannot be read).
    pub fn look(&mut self) -> Vec<Busy> {
        let now = (std::time::Instant::now(), processes());
        let own = std::process::id();
        let mut busy = Vec::new();
        if let Some((t, before)) = &self.last {
            let wall = now.0.duration_since(*t).as_secs_f64();
            if wall > 0.05 {
                for p in &now.1 {
                    // A process new since the last look spent all its CPU
                    // since then.
                    let then = before
                        .iter()
                        .find(|b| b.pid == p.pid)
                        .map_or(0.0, |b| b.cpu_s);
                    let cores = (p.cpu_s - then).max(0.0) / wall;
                    if p.pid != own && cores >= 0.1 {
                        busy.push(Busy {
                            pid: p.pid,
                            name: p.name.clone(),
                            cores,
                        });
                    }
                }
            }
        }
        busy.sort_by(|a, b| b.cores.total_cmp(&a.cores));
        self.last = Some(now);
        busy
    }
}

/// The busiest of `busy` in words: `stress (pid 12) 1.0 core, ...`.
pub fn describe(busy: &[Busy], most: usize) -> String {
    let mut words: Vec<String> = busy
        .iter()
        .take(most)
        .map(|b| format!("{} (pid {}) {:.1} core", b.name, b.pid, b.cores))
        .collect();
    if busy.len() > most {
        words.push(format!("{} more", busy.len() - most));
    }
    words.join(", ")
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    /// The calling thread's own CPU time (s).
    fn own_cpu_s() -> f64 {
        let mut t = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: a valid clock id and a pointer to a timespec we own.
        unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
        t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
    }

    /// Busy work on the calling thread until it has had `cpu_s` of CPU,
    /// or `most` of wall time has passed (a thread of the idle class on a
    /// loaded machine may get none): the CPU it had. A test of who is
    /// counted must not depend on how busy the machine is.
    fn spin(cpu_s: f64, most: std::time::Duration) -> f64 {
        let start = own_cpu_s();
        let until = std::time::Instant::now() + most;
        let mut x = 1u64;
        while own_cpu_s() - start < cpu_s && std::time::Instant::now() < until {
            for _ in 0..10_000 {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1);
            }
            std::hint::black_box(x);
        }
        own_cpu_s() - start
    }

    /// CPU seconds the acquisition's threads spend while a thread (in the
    /// idle class, named as the view's, or neither) spins for 0.4 s of its
    /// own CPU, read while it is alive (an ended thread leaves
    /// `/proc/self/task`), and the thread's own CPU.
    fn spent_while_spinning(idle: bool, name: &str) -> (f64, f64) {
        let (spun, read) = (std::sync::mpsc::channel(), std::sync::mpsc::channel::<()>());
        let before = acquisition_cpu_s().unwrap();
        let t = std::thread::Builder::new()
            .name(name.into())
            .spawn(move || {
                if idle {
                    super::super::lower_priority();
                }
                let had = spin(0.4, std::time::Duration::from_secs(30));
                spun.0.send(had).unwrap();
                read.1.recv().unwrap();
            })
            .unwrap();
        let had = spun.1.recv().unwrap();
        let spent = acquisition_cpu_s().unwrap() - before;
        read.0.send(()).unwrap();
        t.join().unwrap();
        (spent, had)
    }

    /// CPU spent in the idle class or by a thread of the view is not the
    /// acquisition's; CPU spent by an ordinary thread is (whatever else
    /// the machine is doing: each thread spins for CPU time, not wall
    /// time; the clock's ticks are 10 ms).
    #[test]
    fn the_acquisitions_cpu_leaves_out_the_view() {
        let (busy, had) = spent_while_spinning(false, "worker");
        assert!(
            busy >= had - 0.05,
            "an ordinary thread's {had} s: counted {busy}"
        );
        for (idle, name) in [(true, "worker"), (false, "live-server")] {
            let (counted, had) = spent_while_spinning(idle, name);
            assert!(
                counted <= 0.05 + 0.25 * had,
                "{name} (idle class {idle}): {counted} s of its {had} s counted"
            );
        }
    }

    /// Threads' CPU time is read by their name; another process that
    /// spins is named with the cores it took.
    #[test]
    fn a_spinning_process_is_seen_by_name() {
        let t = std::thread::Builder::new()
            .name("cpu-test-spin".into())
            .spawn(|| {
                let before = threads_cpu_s("cpu-test-").unwrap();
                let had = spin(0.3, std::time::Duration::from_secs(30));
                let after = threads_cpu_s("cpu-test-").unwrap();
                assert!(had >= 0.3, "an ordinary thread had {had} s in 30 s");
                (before, after, threads_cpu_s("no-such-thread-").unwrap())
            })
            .unwrap();
        let (before, after, none) = t.join().unwrap();
        assert!(after - before > 0.15, "{before} -> {after}");
        assert_eq!(none, 0.0);
        let mut others = OtherProcesses::new();
        let mut child = std::process::Command::new("sh")
            .args(["-c", "while :; do :; done"])
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(800));
        let busy = others.look();
        child.kill().unwrap();
        child.wait().unwrap();
        let seen = busy.iter().find(|b| b.pid == child.id());
        assert!(seen.is_some_and(|b| b.name == "sh"), "{busy:?}");
        assert!(describe(&busy, 3).contains(&format!("sh (pid {})", child.id())));
    }
}
