//! CPU time of the threads that render a frame (issue 38: where do the cores wait?).
//!
//! `--stats` gives each frame's wall time by phase; set beside the CPU time the render's
//! threads spent over the same span (the rayon pool's threads and the frame loop's), it
//! says how much of the frame kept every thread busy: `cpu / (wall × threads)` is the
//! frame's parallel efficiency, and `(threads × wall − cpu) / (threads − 1)` bounds the
//! time during which only one thread worked (idle threads spin briefly before they
//! sleep, and that spinning counts as CPU time, so the bound is low, never high).
//!
//! Linux only: each thread's time on a CPU, in nanoseconds, is the first number of
//! `/proc/self/task/TID/schedstat`, and a thread learns its TID from the link
//! `/proc/thread-self`. Elsewhere [`CpuClock::of_pool`] answers `None` and the figure is
//! left out. The kernel brings a running thread's figure up to date at scheduler ticks
//! and switches (every 1 to 4 ms), so a frame's figure is good to a few ticks: telling
//! for frames of tens of milliseconds, not for toy ones. The writer's threads (the EXR encoder) are not counted: they overlap the
//! next frame, and `write_ms` is theirs.

use std::path::PathBuf;

/// The CPU time of a fixed set of threads.
#[derive(Clone, Debug)]
pub(crate) struct CpuClock {
    files: Vec<PathBuf>,
}

/// The calling thread's id, from `/proc/thread-self` (a link to `PID/task/TID`).
fn tid() -> Option<String> {
    let link = std::fs::read_link("/proc/thread-self").ok()?;
    Some(link.file_name()?.to_str()?.to_string())
}

impl CpuClock {
    /// The threads of the current rayon pool and the calling thread; `None` where the
    /// system does not say (not Linux).
    pub(crate) fn of_pool() -> Option<CpuClock> {
        let mut tids: Vec<String> = rayon::broadcast(|_| tid())
            .into_iter()
            .collect::<Option<Vec<String>>>()?;
        tids.push(tid()?);
        tids.sort();
        tids.dedup();
        let files: Vec<PathBuf> = tids
            .iter()
            .map(|t| PathBuf::from(format!("/proc/self/task/{t}/schedstat")))
            .collect();
        let clock = CpuClock { files };
        clock.now_ns().map(|_| clock)
    }

    /// The threads' CPU time so far, nanoseconds; `None` when a file cannot be read (a
    /// thread gone).
    pub(crate) fn now_ns(&self) -> Option<u64> {
        let mut sum = 0u64;
        for f in &self.files {
            let text = std::fs::read_to_string(f).ok()?;
            sum = sum.saturating_add(text.split_whitespace().next()?.parse().ok()?);
        }
        Some(sum)
    }

    /// Milliseconds of CPU time since `start` (a [`now_ns`](Self::now_ns) reading).
    pub(crate) fn ms_since(&self, start: Option<u64>) -> Option<f64> {
        let (a, b) = (start?, self.now_ns()?);
        Some(b.saturating_sub(a) as f64 * 1e-6)
    }

    /// How many threads it counts.
    pub(crate) fn threads(&self) -> usize {
        self.files.len()
    }
}

#[cfg(test)]
mod tests {
    use super::CpuClock;

    /// Busy work on every pool thread shows as CPU time, several threads' worth when the
    /// pool has several (on Linux; elsewhere there is no clock to check).
    #[test]
    fn counts_the_pools_busy_time() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .expect("pool");
        pool.install(|| {
            let Some(clock) = CpuClock::of_pool() else {
                if cfg!(target_os = "linux") {
                    panic!("no CPU clock on Linux");
                }
                return;
            };
            assert!(clock.threads() >= 2, "{clock:?}");
            let start = clock.now_ns();
            let wall = std::time::Instant::now();
            // Each thread spins until it has had 50 ms on a CPU (by its own clock: on a
            // loaded machine a thread spinning 50 ms of wall time may get far less).
            rayon::broadcast(|_| {
                let own = || -> u64 {
                    std::fs::read_to_string("/proc/thread-self/schedstat")
                        .ok()
                        .and_then(|t| t.split_whitespace().next()?.parse().ok())
                        .unwrap_or(u64::MAX)
                };
                let t0 = own();
                let mut x = 0u64;
                // (An unreadable clock, u64::MAX, ends the loop at once.)
                while own().saturating_sub(t0) < 50_000_000 && t0 != u64::MAX {
                    for _ in 0..10_000 {
                        x = std::hint::black_box(
                            x.wrapping_mul(6364136223846793005).wrapping_add(1),
                        );
                    }
                }
            });
            let cpu = clock.ms_since(start).expect("cpu time");
            let wall = wall.elapsed().as_secs_f64() * 1e3;
            // Two threads busy 50 ms each: at least 100 ms of CPU, and no more than two
            // threads can spend in the wall time it took.
            assert!(cpu >= 100.0, "cpu {cpu} ms over wall {wall} ms");
            assert!(cpu <= 2.0 * wall + 5.0, "cpu {cpu} ms over wall {wall} ms");
        });
    }
}
