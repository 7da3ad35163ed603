//! Helpers shared by the end-to-end tests.
#![allow(dead_code)]

pub(crate) mod certs;
pub(crate) mod cluster;
