//! A bounded, lock-free single-producer / single-consumer ring of preallocated slots.
//!
//! Slots are created once (with whatever buffers they need) and reused: the producer fills a
//! slot in place, the consumer reads it in place, so neither side allocates. The two indices are
//! monotonic counters on separate cache lines; the producer publishes a filled slot with a
//! `Release` store of `head`, the consumer returns it with a `Release` store of `tail`.

use std::cell::UnsafeCell;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

/// Keeps the producer's and the consumer's counters on separate cache lines.
#[repr(align(128))]
struct Padded<T>(T);

pub struct SpscRing<T> {
    slots: Box<[UnsafeCell<T>]>,
    /// Items pushed so far (written by the producer only).
    head: Padded<AtomicUsize>,
    /// Items popped so far (written by the consumer only).
    tail: Padded<AtomicUsize>,
    /// Pushes dropped because the ring was full (see [`Producer::push_or_drop`]).
    overflow: AtomicU64,
}

// SAFETY: a slot is accessed by the producer only while `head − tail < capacity` says it is
// free, and by the consumer only while `tail < head` says it is filled; the acquire/release
// pairs on `head`/`tail` order those accesses. `Producer`/`Consumer` take `&mut self`, and
// `split` hands out one of each per exclusive borrow of the ring, so there is one of each.
unsafe impl<T: Send> Sync for SpscRing<T> {}

impl<T> SpscRing<T> {
    /// A ring of `capacity ≥ 1` slots, each made by `make`.
    pub fn new(capacity: usize, mut make: impl FnMut() -> T) -> Self {
        assert!(capacity >= 1, "ring capacity must be at least 1");
        Self {
            slots: (0..capacity).map(|_| UnsafeCell::new(make())).collect(),
            head: Padded(AtomicUsize::new(0)),
            tail: Padded(AtomicUsize::new(0)),
            overflow: AtomicU64::new(0),
        }
    }

    pub fn capacity(&self) -> usize {
        self.slots.len()
    }

    /// Items currently in the ring (a snapshot).
    pub fn len(&self) -> usize {
        let tail = self.tail.0.load(Ordering::Acquire);
        self.head.0.load(Ordering::Acquire).wrapping_sub(tail)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Pushes dropped by [`Producer::push_or_drop`] because the ring was full.
    pub fn overflows(&self) -> u64 {
        self.overflow.load(Ordering::Relaxed)
    }

    /// The producer and the consumer handle (one of each).
    pub fn split(&mut self) -> (Producer<'_, T>, Consumer<'_, T>) {
        (Producer { ring: self }, Consumer { ring: self })
    }
}

/// The writing end; `Send` when `T` is, not `Clone`.
pub struct Producer<'a, T> {
    ring: &'a SpscRing<T>,
}

impl<T> Producer<'_, T> {
    /// Fill the next free slot in place with `fill` and publish it; `false` (and `fill` not
    /// called) if the ring is full.
    pub fn try_push_with(&mut self, fill: impl FnOnce(&mut T)) -> bool {
        let r = self.ring;
        let head = r.head.0.load(Ordering::Relaxed);
        let tail = r.tail.0.load(Ordering::Acquire);
        if head.wrapping_sub(tail) >= r.slots.len() {
            return false;
        }
        // SAFETY: the slot at `head` is free (see the `Sync` impl) and only this producer
        // writes free slots.
        fill(unsafe { &mut *r.slots[head % r.slots.len()].get() });
        r.head.0.store(head.wrapping_add(1), Ordering::Release);
        true
    }

    /// As [`Producer::try_push_with`], but a push onto a full ring is dropped and counted.
    pub fn push_or_drop(&mut self, fill: impl FnOnce(&mut T)) -> bool {
        let pushed = self.try_push_with(fill);
        if !pushed {
            self.ring.overflow.fetch_add(1, Ordering::Relaxed);
        }
        pushed
    }
}

/// The reading end; `Send` when `T` is, not `Clone`.
pub struct Consumer<'a, T> {
    ring: &'a SpscRing<T>,
}

impl<T> Consumer<'_, T> {
    /// Read (and possibly modify) the oldest item in place with `read`, then free its slot;
    /// `None` if the ring is empty.
    pub fn try_pop_with<R>(&mut self, read: impl FnOnce(&mut T) -> R) -> Option<R> {
        let r = self.ring;
        let tail = r.tail.0.load(Ordering::Relaxed);
        let head = r.head.0.load(Ordering::Acquire);
        if tail == head {
            return None;
        }
        // SAFETY: the slot at `tail` is filled (see the `Sync` impl) and only this consumer
        // reads filled slots.
        let out = read(unsafe { &mut *r.slots[tail % r.slots.len()].get() });
        r.tail.0.store(tail.wrapping_add(1), Ordering::Release);
        Some(out)
    }
}

/// A ring shared by two threads that own their ends (no borrow of a ring on the stack): made
/// with [`owned_ring`], one producer and one consumer per ring.
pub struct OwnedProducer<T> {
    ring: std::sync::Arc<SpscRing<T>>,
}

/// The reading end of an [`owned_ring`].
pub struct OwnedConsumer<T> {
    ring: std::sync::Arc<SpscRing<T>>,
}

/// A ring of `capacity` slots made by `make`, split into owned ends. The ring is created here
/// and never handed out, so there is exactly one producer and one consumer (the condition of
/// the `Sync` impl).
pub fn owned_ring<T>(capacity: usize, make: impl FnMut() -> T) -> (OwnedProducer<T>, OwnedConsumer<T>) {
    let ring = std::sync::Arc::new(SpscRing::new(capacity, make));
    (OwnedProducer { ring: ring.clone() }, OwnedConsumer { ring })
}

impl<T> OwnedProducer<T> {
    /// See [`Producer::push_or_drop`].
    pub fn push_or_drop(&mut self, fill: impl FnOnce(&mut T)) -> bool {
        Producer { ring: &self.ring }.push_or_drop(fill)
    }
    /// Pushes dropped because the ring was full.
    pub fn overflows(&self) -> u64 {
        self.ring.overflows()
    }
}

impl<T> OwnedConsumer<T> {
    /// See [`Consumer::try_pop_with`].
    pub fn try_pop_with<R>(&mut self, read: impl FnOnce(&mut T) -> R) -> Option<R> {
        Consumer { ring: &self.ring }.try_pop_with(read)
    }
    pub fn overflows(&self) -> u64 {
        self.ring.overflows()
    }
}
