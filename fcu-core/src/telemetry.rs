//! Telemetry lines (being built).
