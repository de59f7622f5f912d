//! Cooperative cancellation of long calls. A caller that can be interrupted (the Python
//! bindings, on Ctrl-C) runs the work inside [`scope`] with a [`CancelFlag`]; the work's long
//! loops ask [`requested`] between iterations and stop, and the stage that owns a result
//! returns [`Error::Cancelled`] through [`check`] so that nothing half-built is kept or cached.
//!
//! The flag travels in a thread-local: [`crate::with_threads`] carries it into its pool, and a
//! parallel loop takes a [`Token`] with [`current`] before it starts, because rayon's worker
//! threads do not see the caller's thread-locals. Outside a scope nothing is ever cancelled.

use std::cell::RefCell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use crate::error::{Error, Result};

/// The switch a caller keeps to cancel the work it started inside [`scope`].
#[derive(Debug, Clone, Default)]
pub struct CancelFlag(Arc<AtomicBool>);

impl CancelFlag {
    /// A flag not yet raised.
    pub fn new() -> Self {
        Self::default()
    }

    /// Asks the work to stop at its next check.
    pub fn cancel(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Whether [`cancel`](Self::cancel) was called.
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

/// The current call's flag, as a parallel loop carries it into rayon's workers.
#[derive(Debug, Clone, Default)]
pub struct Token(Option<CancelFlag>);

impl Token {
    /// Whether the call this token belongs to was cancelled.
    #[inline]
    pub fn requested(&self) -> bool {
        self.0.as_ref().is_some_and(CancelFlag::is_cancelled)
    }
}

thread_local! {
    static CURRENT: RefCell<Option<CancelFlag>> = const { RefCell::new(None) };
}

/// Restores the thread's previous flag when a scope ends, panics included.
struct Restore(Option<CancelFlag>);

impl Drop for Restore {
    fn drop(&mut self) {
        let previous = self.0.take();
        CURRENT.with(|c| *c.borrow_mut() = previous);
    }
}

/// Runs `work` with `token`'s flag as this thread's current one.
pub(crate) fn enter<R>(token: Token, work: impl FnOnce() -> R) -> R {
    let previous = CURRENT.with(|c| std::mem::replace(&mut *c.borrow_mut(), token.0));
    let _restore = Restore(previous);
    work()
}

/// Runs `work` so that raising `flag` makes its long loops stop and its result
/// [`Error::Cancelled`].
pub fn scope<R>(flag: &CancelFlag, work: impl FnOnce() -> R) -> R {
    enter(Token(Some(flag.clone())), work)
}

/// The current call's token, for the closures of a parallel loop.
pub fn current() -> Token {
    Token(CURRENT.with(|c| c.borrow().clone()))
}

/// Whether the current call was cancelled (false outside a [`scope`]).
#[inline]
pub fn requested() -> bool {
    CURRENT.with(|c| c.borrow().as_ref().is_some_and(CancelFlag::is_cancelled))
}

/// `Err(Error::Cancelled)` once the current call was cancelled.
pub fn check() -> Result<()> {
    if requested() {
        Err(Error::Cancelled)
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outside_a_scope_nothing_is_cancelled() {
        assert!(!requested());
        assert!(check().is_ok());
        assert!(!current().requested());
    }

    #[test]
    fn a_raised_flag_is_seen_in_its_scope_and_in_the_pool_only() {
        let flag = CancelFlag::new();
        scope(&flag, || {
            assert!(check().is_ok());
            flag.cancel();
            assert_eq!(check(), Err(Error::Cancelled));
            let seen_in_pool = crate::with_threads(2, requested);
            assert!(seen_in_pool, "with_threads carries the flag into its pool");
            let token = current();
            let seen_by_workers = std::thread::scope(|s| s.spawn(move || token.requested()).join().unwrap());
            assert!(seen_by_workers);
        });
        assert!(!requested(), "the flag ends with its scope");
        let other = CancelFlag::new();
        scope(&other, || assert!(!requested(), "another call's flag is its own"));
    }

    /// Every long call stops with `Cancelled` once its flag is up, and runs to its result otherwise.
    #[test]
    fn long_calls_end_cancelled_in_a_raised_scope() {
        use crate::geometry::Point;
        use crate::{
            estimate_normals, icp, parts, IcpConfig, IcpMethod, IcpTarget, KdIndex, Orientation, PpfConfig, PpfModel,
        };
        use nalgebra::Isometry3;
        let tee = parts::tee(&parts::TeeParams::default()).unwrap();
        let s = crate::sample_surface(&tee.mesh, crate::Density::Count(2000), 1).unwrap();
        let index = KdIndex::new(&s.points);
        let cfg = IcpConfig {
            method: IcpMethod::PointToPoint,
            ..IcpConfig::default()
        };
        let target = IcpTarget::new(s.points.clone(), None).unwrap();
        let shifted: Vec<Point> = s
            .points
            .iter()
            .map(|p| p + nalgebra::Vector3::new(0.5, 0.0, 0.0))
            .collect();
        let model = crate::PoseModel::new(s.points.clone(), s.normals.clone(), 100.0, 1e4, None).unwrap();
        let pose_cfg = crate::PoseConfig {
            method: crate::CoarseMethod::Centroid,
            ..crate::PoseConfig::default()
        };
        let calls = |expect_cancelled: bool| {
            let outcomes = [
                estimate_normals(
                    &s.points,
                    &index,
                    10,
                    Orientation::TowardDirection(nalgebra::Vector3::z()),
                )
                .err(),
                icp(&shifted, &target, &Isometry3::identity(), &cfg).err(),
                PpfModel::new(s.points.clone(), s.normals.clone(), 100.0, PpfConfig::default()).err(),
                parts::tee(&parts::TeeParams::default()).err(),
                crate::estimate_poses(&s.points, &model, &pose_cfg).err(),
            ];
            for (i, e) in outcomes.into_iter().enumerate() {
                match (expect_cancelled, e) {
                    (true, e) => assert_eq!(e, Some(Error::Cancelled), "call {i}"),
                    // The centroid pose of a lone part may be found or not; it is never cancelled.
                    (false, e) => assert!(
                        e.is_none() || (i == 4 && e != Some(Error::Cancelled)),
                        "call {i}: {e:?}"
                    ),
                }
            }
        };
        calls(false);
        let flag = CancelFlag::new();
        scope(&flag, || calls(false));
        flag.cancel();
        scope(&flag, || calls(true));
    }
}
