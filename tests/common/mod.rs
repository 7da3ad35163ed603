//! Helpers shared by the end-to-end tests.
#![allow(dead_code)]

pub(crate) mod certs;
pub(crate) mod cluster;

/// A loopback TCP port nothing listens on, never the same twice in this
/// test process: tests run in parallel, and the operating system may hand
/// a port it just freed to the next test before the first test's server
/// has bound it, which would put two tests' servers on one port.
pub(crate) fn free_port() -> u16 {
    static GIVEN: std::sync::Mutex<Vec<u16>> = std::sync::Mutex::new(Vec::new());
    let mut given = GIVEN.lock().unwrap_or_else(|e| e.into_inner());
    loop {
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        if !given.contains(&port) {
            given.push(port);
            return port;
        }
    }
}
