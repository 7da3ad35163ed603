//! The process's resident memory and the limit a run holds it to: what
//! the watchdog compares, so that a component that keeps allocating ends
//! the run with a named failure (metrics written) rather than the
//! kernel's OOM kill (nothing written).

/// The process's resident memory, bytes (`VmRSS` in `/proc/self/status`);
/// `None` where that cannot be read.
pub(crate) fn resident_bytes() -> Option<u64> {
    status_kib("VmRSS:").map(|kib| kib << 10)
}

/// The value in kB of the line `key` of `/proc/self/status` (`VmRSS:`,
/// `VmHWM:`); `None` where that cannot be read.
pub(crate) fn status_kib(key: &str) -> Option<u64> {
    kib_field(&std::fs::read_to_string("/proc/self/status").ok()?, key)
}

/// The limit a run gets unless its topology sets one: 90% of what the
/// machine holds, or of the cgroup's `memory.max` when lower (a
/// container's limit); `None` where neither can be read.
pub(crate) fn default_limit() -> Option<u64> {
    let total = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| kib_field(&m, "MemTotal:"))
        .map(|k| k << 10);
    let cgroup =
        std::fs::read_to_string("/sys/fs/cgroup/memory.max").ok().and_then(|m| m.trim().parse::<u64>().ok());
    let allowed = match (total, cgroup) {
        (Some(t), Some(c)) => t.min(c),
        (t, c) => t.or(c)?,
    };
    Some(allowed / 10 * 9)
}

/// The value in kB of the line starting with `key` in a `/proc` file.
fn kib_field(text: &str, key: &str) -> Option<u64> {
    let value = text.lines().find_map(|l| l.strip_prefix(key))?;
    value.trim().strip_suffix("kB")?.trim().parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_kernels_figures() {
        assert_eq!(kib_field("Name:\tx\nVmRSS:\t  1234 kB\n", "VmRSS:"), Some(1234));
        assert_eq!(kib_field("VmRSS: lots\n", "VmRSS:"), None);
        if cfg!(target_os = "linux") {
            let rss = resident_bytes().unwrap();
            let limit = default_limit().unwrap();
            assert!(rss > 0 && rss < limit, "rss {rss}, limit {limit}");
        }
    }
}
