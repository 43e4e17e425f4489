//! The host's memory as Linux reports it: what a job may still take, and the most it has held,
//! so that a render too large for the machine is refused before it starts rather than killed
//! midway by the kernel's out-of-memory killer (which no signal handler sees: the render's
//! temporary files would stay behind), and so that its peak can be reported.

/// Bytes the host can still give this process without swapping, as far as Linux says:
/// `MemAvailable` of `/proc/meminfo`, capped by the process's cgroup v2 limit (`memory.max`, as a
/// container sets it) where there is one. An estimate (other processes allocate too); `None`
/// where `/proc/meminfo` cannot be read (not Linux).
pub fn available_bytes() -> Option<u64> {
    let available = kib_field(&std::fs::read_to_string("/proc/meminfo").ok()?, "MemAvailable")?;
    let limit = std::fs::read_to_string("/proc/self/cgroup").ok().and_then(|groups| {
        let path = cgroup_v2_path(&groups)?;
        cgroup_limit(&std::fs::read_to_string(format!("/sys/fs/cgroup{path}/memory.max")).ok()?)
    });
    Some(limit.map_or(available, |limit| limit.min(available)))
}

/// The most resident memory this process has held so far, bytes: `VmHWM` of `/proc/self/status`;
/// `None` where it cannot be read (not Linux).
pub fn peak_resident_bytes() -> Option<u64> {
    kib_field(&std::fs::read_to_string("/proc/self/status").ok()?, "VmHWM")
}

/// The value of a `/proc` line `key:   N kB`, in bytes.
fn kib_field(text: &str, key: &str) -> Option<u64> {
    let line = text.lines().find_map(|line| line.strip_prefix(key)?.strip_prefix(':'))?;
    match line.split_whitespace().collect::<Vec<_>>()[..] {
        [kib, "kB"] => kib.parse::<u64>().ok()?.checked_mul(1024),
        _ => None,
    }
}

/// The process's cgroup v2 path, from `/proc/self/cgroup`'s `0::PATH` line.
fn cgroup_v2_path(groups: &str) -> Option<&str> {
    groups.lines().find_map(|line| line.strip_prefix("0::"))
}

/// A cgroup v2 `memory.max`: bytes, or `None` for `max` (no limit).
fn cgroup_limit(text: &str) -> Option<u64> {
    text.trim().parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn proc_fields_and_cgroup_limits_are_read() {
        let meminfo = "MemTotal:       24684084 kB\nMemFree:        19000000 kB\nMemAvailable:   24103152 kB\n";
        assert_eq!(kib_field(meminfo, "MemAvailable"), Some(24_103_152 * 1024));
        assert_eq!(kib_field(meminfo, "MemTotal"), Some(24_684_084 * 1024));
        // A key is matched whole, and a line without its unit is not taken.
        assert_eq!(kib_field(meminfo, "Mem"), None);
        assert_eq!(kib_field("VmHWM:\t  1482976 kB\n", "VmHWM"), Some(1_482_976 * 1024));
        assert_eq!(kib_field("VmHWM: 12\n", "VmHWM"), None);
        assert_eq!(cgroup_v2_path("4:memory:/a\n0::/user.slice/x.scope\n"), Some("/user.slice/x.scope"));
        assert_eq!(cgroup_v2_path("4:memory:/a\n"), None);
        assert_eq!(cgroup_limit("8589934592\n"), Some(8 << 30));
        assert_eq!(cgroup_limit("max\n"), None);
    }

    /// On Linux both are read, and the peak of a process that has just touched 64 MiB is at least
    /// that.
    #[cfg(target_os = "linux")]
    #[test]
    fn this_machine_reports_its_memory() {
        assert!(available_bytes().is_some_and(|bytes| bytes > 0));
        let touched = vec![1u8; 64 << 20];
        assert!(peak_resident_bytes().unwrap() >= touched.len() as u64);
        std::hint::black_box(touched);
    }
}
