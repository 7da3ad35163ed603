//! squall-spouts: sources — log readers (CARMEN, ROS 2 bags), simulators and
//! network ingest.
//!
//! Empty until the robot data work lands (issue 3); the crate exists now so
//! the workspace layout is the one DESIGN.md describes.
