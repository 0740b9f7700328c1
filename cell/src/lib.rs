//! The cell orchestrator library.
