//! The host's memory as Linux reports it: what a job may still take, and the most it has held,
//! so that a render too large for the machine is refused before it starts rather than killed
//! midway by the kernel's out-of-memory killer (which no signal handler sees: the render's
//! temporary files would stay behind), and so that its peak can be reported.

/// Bytes the host can still give this process without swapping, as far as Linux says:
/// `MemAvailable` of `/proc/meminfo`, capped by what the memory limits of the process's cgroups
/// leave it (v2 or v1, as a container sets them: each limit of its group and the groups above,
/// less their usage that is not page cache). An estimate (other processes allocate too);
/// `None` where `/proc/meminfo` cannot be read (not Linux).
pub fn available_bytes() -> Option<u64> {
    let available = kib_field(&std::fs::read_to_string("/proc/meminfo").ok()?, "MemAvailable")?;
    let headroom = std::fs::read_to_string("/proc/self/cgroup")
        .ok()
        .and_then(|groups| cgroup_headroom(&groups, |path| std::fs::read_to_string(path).ok()));
    Some(headroom.map_or(available, |headroom| headroom.min(available)))
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

/// A cgroup v1 memory limit at or above this is "no limit" (the kernel writes
/// `PAGE_COUNTER_MAX` pages, 2⁶³ − 4096 bytes with 4 KiB pages).
const V1_UNLIMITED: u64 = 1 << 62;

/// What the memory limits of the process's cgroups (`groups`, the text of `/proc/self/cgroup`)
/// leave it, reading each control file's text with `read` (a path under `/sys/fs/cgroup`): the
/// least, over the limits that apply, of the limit less the group's usage that is not page cache
/// (`active_file` + `inactive_file`, which the kernel reclaims before it kills, as
/// `MemAvailable` counts it available). Under cgroup v2 the limits are `memory.max` of the
/// process's group and of each ancestor, each against that group's `memory.current`; under v1
/// (a `memory` controller line, also in the hybrid layout) `hierarchical_memory_limit`, the
/// least of the group's and its ancestors', against the group's own `memory.usage_in_bytes` — it
/// leaves out what siblings under a limiting ancestor use. `None` where no limit applies or
/// none can be read.
fn cgroup_headroom(groups: &str, read: impl Fn(&str) -> Option<String>) -> Option<u64> {
    groups
        .lines()
        .filter_map(|line| {
            let mut fields = line.splitn(3, ':');
            let (_, controllers, path) = (fields.next()?, fields.next()?, fields.next()?);
            let path = path.trim_end_matches('/');
            if controllers.is_empty() {
                v2_headroom(path, &read)
            } else if controllers.split(',').any(|controller| controller == "memory") {
                v1_headroom(path, &read)
            } else {
                None
            }
        })
        .min()
}

/// The group at `path` (without its trailing `/`) and each above it, up to the hierarchy's root
/// (""): in a container that mounts its own group as the root without a cgroup namespace, the
/// process's path does not exist there, and the root holds the container's limit.
fn levels(path: &str) -> impl Iterator<Item = &str> {
    std::iter::successors(Some(path), |level| level.rfind('/').map(|slash| &level[..slash]))
}

/// [`cgroup_headroom`] under cgroup v2 for the group at `path`: the least over it and the groups
/// above it ([`levels`]) that set `memory.max`.
fn v2_headroom(path: &str, read: &impl Fn(&str) -> Option<String>) -> Option<u64> {
    levels(path)
        .filter_map(|level| {
            let dir = format!("/sys/fs/cgroup{level}");
            let limit = read(&format!("{dir}/memory.max"))?.trim().parse().ok()?;
            let usage = read(&format!("{dir}/memory.current")).and_then(|text| text.trim().parse().ok());
            let stat = read(&format!("{dir}/memory.stat")).unwrap_or_default();
            Some(headroom(limit, usage, &stat, "active_file", "inactive_file"))
        })
        .min()
}

/// [`cgroup_headroom`] under cgroup v1 for the memory controller's group at `path`: from the
/// nearest of it and the groups above it ([`levels`]) that can be read, since its
/// `hierarchical_memory_limit` already takes in those above.
fn v1_headroom(path: &str, read: &impl Fn(&str) -> Option<String>) -> Option<u64> {
    let (dir, stat) = levels(path).find_map(|level| {
        let dir = format!("/sys/fs/cgroup/memory{level}");
        read(&format!("{dir}/memory.stat")).map(|stat| (dir, stat))
    })?;
    let limit = stat_field(&stat, "hierarchical_memory_limit").filter(|&limit| limit < V1_UNLIMITED)?;
    let usage = read(&format!("{dir}/memory.usage_in_bytes")).and_then(|text| text.trim().parse().ok());
    Some(headroom(limit, usage, &stat, "total_active_file", "total_inactive_file"))
}

/// `limit` less `usage` (0 if unknown) without the page cache that `stat`'s two file-list fields
/// count.
fn headroom(limit: u64, usage: Option<u64>, stat: &str, active_file: &str, inactive_file: &str) -> u64 {
    let cache = stat_field(stat, active_file).unwrap_or(0).saturating_add(stat_field(stat, inactive_file).unwrap_or(0));
    limit.saturating_sub(usage.unwrap_or(0).saturating_sub(cache))
}

/// The value of a cgroup `memory.stat` line `key N` (bytes).
fn stat_field(text: &str, key: &str) -> Option<u64> {
    text.lines().find_map(|line| line.strip_prefix(key)?.strip_prefix(' ')?.trim().parse().ok())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn proc_fields_are_read() {
        let meminfo = "MemTotal:       24684084 kB\nMemFree:        19000000 kB\nMemAvailable:   24103152 kB\n";
        assert_eq!(kib_field(meminfo, "MemAvailable"), Some(24_103_152 * 1024));
        assert_eq!(kib_field(meminfo, "MemTotal"), Some(24_684_084 * 1024));
        // A key is matched whole, and a line without its unit is not taken.
        assert_eq!(kib_field(meminfo, "Mem"), None);
        assert_eq!(kib_field("VmHWM:\t  1482976 kB\n", "VmHWM"), Some(1_482_976 * 1024));
        assert_eq!(kib_field("VmHWM: 12\n", "VmHWM"), None);
    }

    /// A fake `/sys/fs/cgroup` of `(path, text)` files.
    fn files(entries: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let entries: Vec<(String, String)> = entries.iter().map(|(p, t)| (p.to_string(), t.to_string())).collect();
        move |path| entries.iter().find(|(p, _)| p == path).map(|(_, text)| text.clone())
    }

    const GIB: u64 = 1 << 30;

    /// v2: every level that sets `memory.max` counts, its page cache as free; the tightest wins.
    #[test]
    fn cgroup_v2_limits_of_the_group_and_its_ancestors_leave_their_headroom() {
        let groups = "0::/a/b\n";
        let parent_limit = [
            ("/sys/fs/cgroup/a/b/memory.max", "max\n"),
            ("/sys/fs/cgroup/a/b/memory.current", "100\n"),
            ("/sys/fs/cgroup/a/memory.max", "8589934592\n"),
            ("/sys/fs/cgroup/a/memory.current", "5368709120\n"),
            ("/sys/fs/cgroup/a/memory.stat", "anon 3221225472\nactive_file 1073741824\ninactive_file 1073741824\n"),
        ];
        // 8 GiB less the 3 GiB that is not cache: a leaf limit of `max` had read as no limit.
        assert_eq!(cgroup_headroom(groups, files(&parent_limit)), Some(5 * GIB));
        let mut tighter_leaf = parent_limit.to_vec();
        tighter_leaf[0] = ("/sys/fs/cgroup/a/b/memory.max", "1073741924\n");
        assert_eq!(cgroup_headroom(groups, files(&tighter_leaf)), Some(GIB));
        // A group at the root of a container's namespace; usage all cache leaves the whole limit.
        let root = [
            ("/sys/fs/cgroup/memory.max", "2147483648\n"),
            ("/sys/fs/cgroup/memory.current", "1073741824\n"),
            ("/sys/fs/cgroup/memory.stat", "active_file 1073741824\ninactive_file 1073741824\n"),
        ];
        assert_eq!(cgroup_headroom("0::/\n", files(&root)), Some(2 * GIB));
        assert_eq!(cgroup_headroom("0::/a/b\n", files(&[("/sys/fs/cgroup/a/b/memory.max", "max\n")])), None);
        assert_eq!(cgroup_headroom("0::/a/b\n", files(&[])), None);
    }

    /// v1 (the hybrid layout's memory controller too): the hierarchical limit against the
    /// group's usage less its page cache; the kernel's "unlimited" is no limit.
    #[test]
    fn a_cgroup_v1_memory_limit_leaves_its_headroom() {
        let stat = "cache 805306368\nhierarchical_memory_limit 2147483648\ntotal_active_file 536870912\n\
                    total_inactive_file 268435456\n";
        let limited = [
            ("/sys/fs/cgroup/memory/x/memory.stat", stat),
            ("/sys/fs/cgroup/memory/x/memory.usage_in_bytes", "1610612736\n"),
        ];
        for groups in ["4:memory:/x\n0::/\n", "3:cpu,memory:/x\n"] {
            assert_eq!(cgroup_headroom(groups, files(&limited)), Some(GIB + GIB / 4), "{groups}");
        }
        // A container's own group mounted as the root, its path in the host's hierarchy absent.
        let container = [
            ("/sys/fs/cgroup/memory/memory.stat", stat),
            ("/sys/fs/cgroup/memory/memory.usage_in_bytes", "1610612736\n"),
        ];
        assert_eq!(cgroup_headroom("4:memory:/docker/abc\n", files(&container)), Some(GIB + GIB / 4));
        let unlimited = [("/sys/fs/cgroup/memory/x/memory.stat", "hierarchical_memory_limit 9223372036854771712\n")];
        assert_eq!(cgroup_headroom("4:memory:/x\n", files(&unlimited)), None);
        assert_eq!(cgroup_headroom("4:cpu:/x\n", files(&limited)), None);
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
