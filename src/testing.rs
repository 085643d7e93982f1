//! Procedural test scenes (stub: being written).
