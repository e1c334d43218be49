//! Scoring attitude estimators on BROAD recordings (being built).
