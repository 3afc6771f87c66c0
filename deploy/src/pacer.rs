//! [`Pacer`]: a deadline-based fixed-rate loop clock. Deadlines advance by exactly one period from
//! the start (no drift from compute time, unlike `sleep(period)`); a tick that starts more than a
//! period late is an overrun and the schedule skips ahead instead of bursting to catch up.

use std::time::{Duration, Instant};

#[derive(Debug)]
pub struct Pacer {
    period: Duration,
    next: Instant,
    last_wake: Option<Instant>,
    /// Ticks that started more than one period after their deadline.
    pub overruns: u64,
}

/// Sleep granularity: sleep until this close to the deadline, then yield-spin.
const SPIN: Duration = Duration::from_micros(300);

impl Pacer {
    pub fn new(period: Duration) -> Self {
        Self {
            period,
            next: Instant::now() + period,
            last_wake: None,
            overruns: 0,
        }
    }

    pub fn period(&self) -> Duration {
        self.period
    }

    /// Waits for the next deadline; returns the wake time and the time since the previous wake
    /// (`None` on the first tick).
    pub fn wait(&mut self) -> (Instant, Option<Duration>) {
        let now = Instant::now();
        if self.next > now + SPIN {
            std::thread::sleep(self.next - now - SPIN);
        }
        while Instant::now() < self.next {
            std::thread::yield_now();
        }
        let woke = Instant::now();
        if woke > self.next + self.period {
            self.overruns += 1;
            self.next = woke;
        }
        self.next += self.period;
        let since = self.last_wake.map(|t| woke - t);
        self.last_wake = Some(woke);
        (woke, since)
    }
}
