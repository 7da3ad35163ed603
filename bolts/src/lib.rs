//! squall-bolts: robotics algorithms as pure modules, and the thin bolts that
//! host them on the engine.
//!
//! Empty until the SLAM and localization work lands (issues 4–6); the crate
//! exists now so the workspace layout is the one DESIGN.md describes.
