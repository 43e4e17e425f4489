//! The host's memory as Linux reports it: what a job may still take, and the most it has held,
//! so that a render too large for the machine is refused before it starts rather than killed
//! midway by the kernel's out-of-memory killer (which no signal handler sees: the render's
//! temporary files would stay behind), and so that its peak can be reported.

/// Bytes the host can still give this process without swapping, as far as Linux says:
/// `MemAvailable` of `/proc/meminfo`, capped by what the memory limits of the process's cgroups
/// leave it (v2 or v1, as a container sets them: each limit of its group and the groups above it
/// that it can see, less their usage that is not clean page cache). An estimate (other processes
/// allocate too); `None` where `/proc/meminfo` cannot be read (not Linux).
pub fn available_bytes() -> Option<u64> {
    let read = |path: &str| std::fs::read_to_string(path).ok();
    let available = kib_field(&read("/proc/meminfo")?, "MemAvailable")?;
    let headroom = read("/proc/self/cgroup")
        .zip(read("/proc/self/mountinfo"))
        .and_then(|(groups, mounts)| cgroup_headroom(&groups, &mounts, read));
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
/// `PAGE_COUNTER_MAX` pages, 2⁶³ less one page, with pages of 4 or 64 KiB).
const V1_UNLIMITED: u64 = 1 << 62;

/// What the memory limits of the process's cgroups leave it: `groups` is the text of
/// `/proc/self/cgroup`, `mounts` that of `/proc/self/mountinfo`, and `read` reads a control
/// file's text. The least, over the limits that apply, of the limit less the group's usage that
/// is not clean page cache (`active_file` + `inactive_file` less the dirty pages and those under
/// writeback, which the kernel reclaims before it kills, as `MemAvailable` counts them
/// available). Under cgroup v2 the limits are `memory.max` of the process's group and of each
/// group above it within the mount, each against that group's `memory.current`; under v1 (a
/// `memory` controller line, also in the hybrid layout) `hierarchical_memory_limit`, the least of
/// the group's and all its ancestors', against the group's own `memory.usage_in_bytes` — which
/// leaves out what siblings under a limiting ancestor use. `None` where no limit applies or
/// none can be read.
fn cgroup_headroom(groups: &str, mounts: &str, read: impl Fn(&str) -> Option<String>) -> Option<u64> {
    groups
        .lines()
        .filter_map(|line| {
            let mut fields = line.splitn(3, ':');
            let (_, controllers, path) = (fields.next()?, fields.next()?, fields.next()?);
            let v1_memory = controllers.split(',').any(|controller| controller == "memory");
            if !controllers.is_empty() && !v1_memory {
                return None;
            }
            let dirs = cgroup_mounts(mounts, v1_memory).filter_map(|mount| mount.group_dirs(path));
            if v1_memory {
                // `hierarchical_memory_limit` already takes in the groups above.
                dirs.filter_map(|mut dirs| v1_headroom(&dirs.next()?, &read)).min()
            } else {
                dirs.flatten().filter_map(|dir| v2_headroom(&dir, &read)).min()
            }
        })
        .min()
}

/// A mounted cgroup hierarchy: the group it shows at its mount point (not `/` in a container
/// without a cgroup namespace, which sees its own group mounted there) and that mount point.
#[derive(Copy, Clone)]
struct CgroupMount<'a> {
    root: &'a str,
    point: &'a str,
}

impl<'a> CgroupMount<'a> {
    /// The directories of the group at `path` (the hierarchy's own path, as `/proc/self/cgroup`
    /// gives it) and of each group above it up to the mount's root; `None` where the group is
    /// not under that root.
    fn group_dirs<'p>(self, path: &'p str) -> Option<impl Iterator<Item = String> + 'p>
    where
        'a: 'p,
    {
        let relative = if self.root == "/" { path } else { path.strip_prefix(self.root)? };
        if !(relative.is_empty() || relative.starts_with('/')) {
            return None;
        }
        let point = self.point.trim_end_matches('/');
        let levels = std::iter::successors(Some(relative.trim_end_matches('/')), |level| {
            level.rfind('/').map(|slash| &level[..slash])
        });
        Some(levels.map(move |level| format!("{point}{level}")))
    }
}

/// The mounts in `mountinfo` (`/proc/self/mountinfo`'s text: root and mount point are its fourth
/// and fifth fields, the file system type and its options the first and third after ` - `) of
/// the v2 hierarchy, or with `v1_memory` of v1's memory controller.
fn cgroup_mounts(mountinfo: &str, v1_memory: bool) -> impl Iterator<Item = CgroupMount<'_>> {
    mountinfo.lines().filter_map(move |line| {
        let (mount, file_system) = line.split_once(" - ")?;
        let mut mount = mount.split(' ').skip(3);
        let (root, point) = (mount.next()?, mount.next()?);
        let mut file_system = file_system.split(' ');
        let (kind, options) = (file_system.next()?, file_system.nth(1).unwrap_or(""));
        let wanted = if v1_memory {
            kind == "cgroup" && options.split(',').any(|option| option == "memory")
        } else {
            kind == "cgroup2"
        };
        wanted.then_some(CgroupMount { root, point })
    })
}

/// [`cgroup_headroom`] under cgroup v2 for the group in directory `dir`, `None` where it sets no
/// `memory.max`.
fn v2_headroom(dir: &str, read: &impl Fn(&str) -> Option<String>) -> Option<u64> {
    let limit = number(read, &format!("{dir}/memory.max"))?;
    let usage = number(read, &format!("{dir}/memory.current"));
    let stat = read(&format!("{dir}/memory.stat")).unwrap_or_default();
    Some(headroom(limit, usage, &stat, ["active_file", "inactive_file", "file_dirty", "file_writeback"]))
}

/// [`cgroup_headroom`] under cgroup v1 for the memory controller's group in directory `dir`.
fn v1_headroom(dir: &str, read: &impl Fn(&str) -> Option<String>) -> Option<u64> {
    let stat = read(&format!("{dir}/memory.stat"))?;
    let limit = stat_field(&stat, "hierarchical_memory_limit").filter(|&limit| limit < V1_UNLIMITED)?;
    let usage = number(read, &format!("{dir}/memory.usage_in_bytes"));
    let cache_fields = ["total_active_file", "total_inactive_file", "total_dirty", "total_writeback"];
    Some(headroom(limit, usage, &stat, cache_fields))
}

/// `limit` less `usage` (0 if unknown) without the clean page cache: `stat`'s two file-list
/// fields (`[active, inactive, …]`) less its dirty and writeback fields (`[…, dirty, writeback]`).
fn headroom(limit: u64, usage: Option<u64>, stat: &str, [active, inactive, dirty, writeback]: [&str; 4]) -> u64 {
    let field = |key| stat_field(stat, key).unwrap_or(0);
    let cache =
        field(active).saturating_add(field(inactive)).saturating_sub(field(dirty).saturating_add(field(writeback)));
    limit.saturating_sub(usage.unwrap_or(0).saturating_sub(cache))
}

/// The number a one-value control file at `path` holds (`None` for `max`, or where unread).
fn number(read: &impl Fn(&str) -> Option<String>, path: &str) -> Option<u64> {
    read(path)?.trim().parse().ok()
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

    /// A fake file system of `(path, text)` files.
    fn files<P: AsRef<str>>(entries: &[(P, &str)]) -> impl Fn(&str) -> Option<String> {
        let entries: Vec<(String, String)> =
            entries.iter().map(|(p, t)| (p.as_ref().to_owned(), t.to_string())).collect();
        move |path| entries.iter().find(|(p, _)| p == path).map(|(_, text)| text.clone())
    }

    const GIB: u64 = 1 << 30;

    /// The v2 hierarchy mounted at `/sys/fs/cgroup`, its root `/` (a host, or a container with a
    /// cgroup namespace).
    const V2_MOUNT: &str = "29 23 0:26 / /sys/fs/cgroup rw,nosuid,nodev,noexec,relatime shared:4 - cgroup2 cgroup2 \
                            rw,nsdelegate,memory_recursiveprot\n";

    /// The hybrid layout this project's VM has: v1 controllers, v2 mounted beside them.
    const HYBRID_MOUNTS: &str = "31 23 0:28 / /sys/fs/cgroup rw,relatime - tmpfs tmpfs rw,mode=755\n\
                                 32 31 0:29 / /sys/fs/cgroup/cpu rw,relatime - cgroup cgroup rw,cpu\n\
                                 35 31 0:32 / /sys/fs/cgroup/memory rw,relatime - cgroup cgroup rw,memory\n\
                                 41 31 0:38 / /sys/fs/cgroup/unified rw,relatime - cgroup2 cgroup2 rw\n";

    /// v2: every level that sets `memory.max` counts, its clean page cache as free; the tightest
    /// wins.
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
        assert_eq!(cgroup_headroom(groups, V2_MOUNT, files(&parent_limit)), Some(5 * GIB));
        let mut tighter_leaf = parent_limit.to_vec();
        tighter_leaf[0] = ("/sys/fs/cgroup/a/b/memory.max", "1073741924\n");
        assert_eq!(cgroup_headroom(groups, V2_MOUNT, files(&tighter_leaf)), Some(GIB));
        // Dirty pages and those under writeback are not free.
        let mut dirty = parent_limit.to_vec();
        dirty[4].1 =
            "active_file 1073741824\ninactive_file 1073741824\nfile_dirty 536870912\nfile_writeback 536870912\n";
        assert_eq!(cgroup_headroom(groups, V2_MOUNT, files(&dirty)), Some(4 * GIB));
        // A group at the root of a container's namespace; usage all cache leaves the whole limit.
        let root = [
            ("/sys/fs/cgroup/memory.max", "2147483648\n"),
            ("/sys/fs/cgroup/memory.current", "1073741824\n"),
            ("/sys/fs/cgroup/memory.stat", "active_file 1073741824\ninactive_file 1073741824\n"),
        ];
        assert_eq!(cgroup_headroom("0::/\n", V2_MOUNT, files(&root)), Some(2 * GIB));
        // A container without a cgroup namespace: its own group, /docker/abc on the host, is
        // mounted as the root; its parent's files are not there to read.
        let own_group = "1010 1003 0:26 /docker/abc /sys/fs/cgroup ro,nosuid - cgroup2 cgroup2 rw\n";
        assert_eq!(cgroup_headroom("0::/docker/abc\n", own_group, files(&root)), Some(2 * GIB));
        // Where v2 is mounted beside v1 (the memory controller still v1's, or not).
        let unified = root.map(|(path, text)| (path.replacen("cgroup", "cgroup/unified", 1), text));
        assert_eq!(cgroup_headroom("0::/\n", HYBRID_MOUNTS, files(&unified)), Some(2 * GIB));
        assert_eq!(cgroup_headroom(groups, V2_MOUNT, files(&[("/sys/fs/cgroup/a/b/memory.max", "max\n")])), None);
        assert_eq!(cgroup_headroom(groups, V2_MOUNT, files::<&str>(&[])), None);
        assert_eq!(cgroup_headroom(groups, "", files(&parent_limit)), None, "no mount, nothing read");
    }

    /// v1 (the hybrid layout's memory controller): the hierarchical limit against the group's
    /// usage less its clean page cache; the kernel's "unlimited" is no limit.
    #[test]
    fn a_cgroup_v1_memory_limit_leaves_its_headroom() {
        let stat = "cache 805306368\nhierarchical_memory_limit 2147483648\ntotal_active_file 536870912\n\
                    total_inactive_file 268435456\n";
        let limited = [
            ("/sys/fs/cgroup/memory/x/memory.stat", stat),
            ("/sys/fs/cgroup/memory/x/memory.usage_in_bytes", "1610612736\n"),
        ];
        for groups in ["4:memory:/x\n0::/\n", "3:cpu,memory:/x\n"] {
            assert_eq!(cgroup_headroom(groups, HYBRID_MOUNTS, files(&limited)), Some(GIB + GIB / 4), "{groups}");
        }
        // A container without a cgroup namespace sees its own group, /docker/abc, at the mount.
        let own_group = "35 31 0:32 /docker/abc /sys/fs/cgroup/memory ro - cgroup cgroup rw,memory\n";
        let container = limited.map(|(path, text)| (path.replace("/x/", "/"), text));
        assert_eq!(cgroup_headroom("4:memory:/docker/abc\n", own_group, files(&container)), Some(GIB + GIB / 4));
        // A group whose name only begins with the mount's root is not under it.
        assert_eq!(cgroup_headroom("4:memory:/docker/abcd\n", own_group, files(&container)), None);
        let unlimited = [("/sys/fs/cgroup/memory/x/memory.stat", "hierarchical_memory_limit 9223372036854771712\n")];
        assert_eq!(cgroup_headroom("4:memory:/x\n", HYBRID_MOUNTS, files(&unlimited)), None);
        assert_eq!(cgroup_headroom("4:cpu:/x\n", HYBRID_MOUNTS, files(&limited)), None);
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
