//! [`Percentiles`]: a bounded window of timing samples (microseconds) with median / p99.

/// The most recent `capacity` samples (a ring), so that percentiles describe recent behaviour and
/// memory stays bounded on a controller that runs for days.
#[derive(Debug, Clone)]
pub struct Percentiles {
    samples: Vec<f32>,
    next: usize,
    capacity: usize,
}

impl Percentiles {
    pub fn new(capacity: usize) -> Self {
        Self {
            samples: Vec::with_capacity(capacity.min(4096)),
            next: 0,
            capacity: capacity.max(1),
        }
    }

    pub fn push(&mut self, value_us: f32) {
        if self.samples.len() < self.capacity {
            self.samples.push(value_us);
        } else {
            self.samples[self.next] = value_us;
        }
        self.next = (self.next + 1) % self.capacity;
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// `(p50, p99)`, nearest-rank; zeros when empty.
    pub fn p50_p99(&self) -> (f64, f64) {
        if self.samples.is_empty() {
            return (0.0, 0.0);
        }
        let mut sorted = self.samples.clone();
        sorted.sort_by(f32::total_cmp);
        let at = |q: f64| {
            let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
            sorted[rank - 1] as f64
        };
        (at(0.50), at(0.99))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_nearest_rank_over_the_window() {
        let mut p = Percentiles::new(100);
        assert_eq!(p.p50_p99(), (0.0, 0.0));
        for v in 1..=100 {
            p.push(v as f32);
        }
        assert_eq!(p.p50_p99(), (50.0, 99.0));
        // The window keeps the newest 100: 101..=200.
        for v in 101..=200 {
            p.push(v as f32);
        }
        assert_eq!(p.len(), 100);
        assert_eq!(p.p50_p99(), (150.0, 199.0));
    }
}
