//! The `l3p bench learner` workload (filled in below).
