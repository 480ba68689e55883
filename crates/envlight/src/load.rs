//! Decoding environment maps from files (being written).
