//! The simulated STEVAL-DRONE01 (being built).
