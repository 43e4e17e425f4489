//! One process-wide lock that keeps the creation and destruction of Vulkan instances and devices
//! apart from every other driver call of the process.
//!
//! Why: NVIDIA's driver (580.159.04 on an H200, measured) deadlocks when one thread creates or
//! destroys a `VkDevice` while another thread uses a different device: the `vkCreateDevice` /
//! `vkDestroyDevice` thread waited on a mutex held by a thread compiling a ray-tracing pipeline,
//! which waited on the driver-wide lock the first one held (stacks taken with eu-stack while test
//! threads each opened, used and dropped their own backends); ordering only pipeline creation
//! against them still hung in 2 of 4 parallel runs. The Vulkan loader also frees its device list
//! without a lock in `vkDestroyDevice` while `vkCreateDevice` walks it
//! (KhronosGroup/Vulkan-Loader#2018), whatever the instance. Both are bugs below raywave, but an
//! engine opening backends from several threads would hang or crash on them, so raywave orders
//! these calls itself: a backend's start and end wait until no other thread is inside a backend
//! call, and backend calls of several threads still run concurrently with each other.

use std::cell::Cell;
use std::sync::{PoisonError, RwLock, RwLockReadGuard, RwLockWriteGuard};

/// The lock itself: it guards no data, only the order of driver calls.
static DRIVER: RwLock<()> = RwLock::new(());

thread_local! {
    /// How many [`DeviceUse`] guards this thread holds (only the outermost takes the lock, so
    /// nested calls cannot queue behind a waiting writer).
    static USES: Cell<usize> = const { Cell::new(0) };
}

/// Held while an instance or device is created or destroyed: no other thread is inside a driver
/// call meanwhile. The calling thread must hold no [`DeviceUse`] (it would wait for itself).
pub(crate) fn device_lifetime() -> RwLockWriteGuard<'static, ()> {
    debug_assert_eq!(USES.with(Cell::get), 0, "a device is created or destroyed inside a device call");
    // The lock guards no data, so a panic while it was held left nothing inconsistent.
    DRIVER.write().unwrap_or_else(PoisonError::into_inner)
}

/// Held across every call into the driver for an open device: a backend method for its whole
/// body, a device object's destruction. Several threads may hold it at once; a thread may nest it.
pub(crate) fn device_use() -> DeviceUse {
    let outermost = USES.with(|uses| {
        uses.set(uses.get() + 1);
        uses.get() == 1
    });
    DeviceUse { _read: outermost.then(|| DRIVER.read().unwrap_or_else(PoisonError::into_inner)) }
}

/// Asserts, in debug builds, that this thread is inside no backend call holding the lock, before
/// host work that takes long or enters rayon (`work` names it). Such work belongs before a
/// backend method takes [`device_use`]: a rayon worker waiting for its parallel section's jobs
/// runs other jobs meanwhile, and one of them that opens or drops a backend would wait for this
/// thread's own lock, forever; and a thread that waits to open or drop a backend makes every
/// other thread's backend calls queue behind the whole of that work.
pub(crate) fn debug_assert_unheld(work: &str) {
    debug_assert_eq!(USES.with(Cell::get), 0, "{work} runs inside a device call, holding the driver lock");
}

/// See [`device_use`].
pub(crate) struct DeviceUse {
    _read: Option<RwLockReadGuard<'static, ()>>,
}

impl Drop for DeviceUse {
    fn drop(&mut self) {
        USES.with(|uses| uses.set(uses.get() - 1));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uses_nest_and_release_the_lock_for_a_lifetime() {
        {
            let _outer = device_use();
            let _inner = device_use();
            assert!(DRIVER.try_write().is_err(), "a use holds the lock against lifetimes");
        }
        assert_eq!(USES.with(Cell::get), 0);
        drop(device_lifetime());
    }

    #[test]
    #[cfg(debug_assertions)]
    fn host_work_inside_a_device_call_is_caught() {
        debug_assert_unheld("outside");
        let inside = std::panic::catch_unwind(|| {
            let _using = device_use();
            debug_assert_unheld("a scan");
        });
        let message = inside.expect_err("host work while the lock is held");
        let message = message.downcast_ref::<String>().expect("a formatted message");
        assert!(message.contains("a scan runs inside a device call"), "{message}");
        assert_eq!(USES.with(Cell::get), 0, "the unwinding released the use");
    }

    #[test]
    fn a_lifetime_waits_for_another_threads_use() {
        let use_held = std::sync::Barrier::new(2);
        let (sender, receiver) = std::sync::mpsc::channel();
        std::thread::scope(|s| {
            s.spawn(|| {
                let _using = device_use();
                use_held.wait();
                std::thread::sleep(std::time::Duration::from_millis(50));
                sender.send("use ended").unwrap();
            });
            use_held.wait();
            let _lifetime = device_lifetime();
            sender.send("lifetime began").unwrap();
        });
        assert_eq!(receiver.try_iter().collect::<Vec<_>>(), ["use ended", "lifetime began"]);
    }
}
