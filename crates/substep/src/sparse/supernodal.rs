//! Single-right-hand-side solves `L Lᵀ x = b` with a supernodal Cholesky factor, written for
//! the one thing a time step needs: stream the factor through the core as fast as memory
//! delivers it (theory §11.4).
//!
//! The factor is faer's (same values, same supernodes, no relaxed amalgamation); only the solve
//! is ours. faer's general solve handles many right-hand sides through its matrix kernels, which
//! for one column costs a dispatch per supernode and reads every `usize` row index; here the
//! values are repacked ([`pack`]) so that a sweep reads the whole factor as one sequential
//! stream: per supernode the lower triangle of the diagonal block (with `1 / L_jj` in place of
//! `L_jj`), then the off-diagonal block in groups of four columns stored row by row. Row
//! indices are `u32`; forward: one update of the gathered right-hand side per group; backward:
//! four dot products per pass over it; on x86-64 the kernels run with AVX2 + FMA when the CPU
//! has them.
//!
//! Optionally ([`SupernodalSolve::enable_second_core`]) the two halves of the elimination tree
//! below its top separator are swept on two cores: a persistent worker thread takes one half,
//! the calling thread the other and then the top. The hand-over is two atomic flags per sweep
//! (no lock, no allocation); the worker spins briefly and then parks between solves.

use crate::error::{Error, Result};
use std::cell::UnsafeCell;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// One supernode: columns `start .. start + ncols` of `L`, with `rows` off-diagonal rows
/// `pattern[pat .. pat + rows]` and values `values[val ..]` in the streaming layout of [`pack`].
#[derive(Debug, Clone, Copy)]
struct Node {
    start: usize,
    ncols: usize,
    rows: usize,
    pat: usize,
    val: usize,
}

/// The read-only factor.
struct Factor {
    nodes: Vec<Node>,
    pattern: Vec<u32>,
    values: HugeBuf,
    use_fma: bool,
}

/// Supernodes `0..a` (columns `0..c1`) and `a..b` (columns `c1..c2`) are independent: no
/// supernode of the first half has a row in `c1..c2`. Supernodes `b..` (columns `c2..n`,
/// the top separators) depend on both.
#[derive(Debug, Clone, Copy)]
struct Split {
    a: usize,
    b: usize,
    c1: usize,
    c2: usize,
}

/// Where one thread's sweep reads and writes `x`: rows `base .. limit` in `own`
/// (`own[p − base]`), rows `≥ limit` in `other` (`other[p − other_base]`).
struct Seg<'a, O> {
    own: &'a mut [f64],
    base: usize,
    limit: usize,
    other: O,
    other_base: usize,
}

/// A supernodal `L` (values in faer's layout) with its fill-reducing permutation.
pub(crate) struct SupernodalSolve {
    n: usize,
    /// `fwd[i]`: the original index of permuted row `i`.
    fwd: Vec<u32>,
    factor: Arc<Factor>,
    /// Permuted right-hand side.
    work: Vec<f64>,
    tmp: Vec<f64>,
    second: Option<SecondCore>,
}

impl SupernodalSolve {
    /// Take faer's supernodal structure and the values of its numeric `L Lᵀ`.
    pub(crate) fn new(
        symbolic: &faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky<usize>,
        perm_fwd: Option<&[usize]>,
        values: Vec<f64>,
    ) -> Result<Self> {
        let n = symbolic.nrows();
        if n > u32::MAX as usize {
            return Err(Error::invalid(
                "structure",
                format!("{n} DOFs are too many for the sparse solver"),
            ));
        }
        let ns = symbolic.n_supernodes();
        let (begin, end) = (symbolic.supernode_begin(), symbolic.supernode_end());
        let col_val = symbolic.col_ptr_for_val();
        let mut nodes = Vec::with_capacity(ns);
        let mut pattern = Vec::new();
        let mut max_rows = 0;
        for s in 0..ns {
            let p = symbolic.supernode(s).pattern();
            let node = Node {
                start: begin[s],
                ncols: end[s] - begin[s],
                rows: p.len(),
                pat: pattern.len(),
                val: col_val[s],
            };
            if col_val[s + 1] - col_val[s] != (node.ncols + node.rows) * node.ncols {
                return Err(Error::numerical("sparse solver", "unexpected supernode layout"));
            }
            pattern.extend(p.iter().map(|&i| i as u32));
            max_rows = max_rows.max(p.len());
            nodes.push(node);
        }
        let packed = pack(&mut nodes, &values);
        drop(values);
        let fwd = match perm_fwd {
            Some(p) => p.iter().map(|&i| i as u32).collect(),
            None => (0..n as u32).collect(),
        };
        Ok(Self {
            n,
            fwd,
            factor: Arc::new(Factor {
                nodes,
                pattern,
                values: HugeBuf::from_slice(&packed),
                use_fma: has_fma(),
            }),
            work: vec![0.0; n],
            tmp: vec![0.0; max_rows],
            second: None,
        })
    }

    /// Stored values of `L` (including the unused upper parts of the diagonal blocks).
    pub(crate) fn len_val(&self) -> usize {
        self.factor.values.len()
    }

    pub(crate) fn n_supernodes(&self) -> usize {
        self.factor.nodes.len()
    }

    /// Bytes read by one solve: the values twice, the row indices twice.
    pub(crate) fn bytes_per_solve(&self) -> usize {
        let vals: usize = self
            .factor
            .nodes
            .iter()
            .map(|s| s.ncols * (s.ncols + 1) / 2 + s.ncols * s.rows)
            .sum();
        2 * (8 * vals + 4 * self.factor.pattern.len())
    }

    /// Whether the sweeps run on two cores.
    pub(crate) fn uses_second_core(&self) -> bool {
        self.second.is_some()
    }

    /// Split the elimination tree below its top separators into two halves of about equal
    /// size and start a worker thread for one of them. `false` (and nothing changes) when the
    /// tree has no such split (a chain-like factor) or the thread cannot be started.
    pub(crate) fn enable_second_core(&mut self) -> bool {
        if self.second.is_some() {
            return true;
        }
        let Some(split) = find_split(&self.factor, self.n) else {
            return false;
        };
        match SecondCore::start(self.factor.clone(), split, self.n, self.tmp.len()) {
            Some(s) => {
                self.second = Some(s);
                true
            }
            None => false,
        }
    }

    /// Overwrite `x` with `A⁻¹ x`.
    pub(crate) fn solve_in_place(&mut self, x: &mut [f64]) {
        assert_eq!(x.len(), self.n);
        if let Some(second) = &mut self.second {
            second.solve(&self.fwd, x, &mut self.tmp);
            return;
        }
        for (w, &f) in self.work.iter_mut().zip(&self.fwd) {
            *w = x[f as usize];
        }
        let n = self.n;
        let f = &*self.factor;
        let all = 0..f.nodes.len();
        forward(f, all.clone(), seg(&mut self.work, 0, n), &mut self.tmp);
        backward(f, all, seg_r(&mut self.work, 0, n), &mut self.tmp);
        for (w, &f) in self.work.iter().zip(&self.fwd) {
            x[f as usize] = *w;
        }
    }
}

/// Repack faer's supernodes (column-major `[L_diag; L_off]` blocks, leading dimension
/// `ncols + rows`, the unused upper half of `L_diag` included) into the order the sweeps read:
/// per supernode the lower triangle of `L_diag` by columns, each column starting with
/// `1 / L_jj` (a division on the chain of dependent updates costs several multiplications),
/// then `L_off` in groups of four columns stored row by row (`rows × w` values, `w ≤ 4`).
/// A sweep then reads the factor as one sequential stream: faer's layout gave the hardware
/// prefetcher four short column streams per group that restart at every supernode (§11.4).
/// Sets each node's `val` to its offset in the result.
fn pack(nodes: &mut [Node], faer_values: &[f64]) -> Vec<f64> {
    let total: usize = nodes
        .iter()
        .map(|s| s.ncols * (s.ncols + 1) / 2 + s.ncols * s.rows)
        .sum();
    let mut out = Vec::with_capacity(total);
    for nd in nodes.iter_mut() {
        let (nc, r, ld) = (nd.ncols, nd.rows, nd.ncols + nd.rows);
        let col = |j: usize| &faer_values[nd.val + j * ld..nd.val + (j + 1) * ld];
        let val = out.len();
        for j in 0..nc {
            let c = col(j);
            out.push(1.0 / c[j]);
            out.extend_from_slice(&c[j + 1..nc]);
        }
        for g in (0..nc).step_by(4) {
            let w = (nc - g).min(4);
            for k in 0..r {
                for l in 0..w {
                    out.push(col(g + l)[nc + k]);
                }
            }
        }
        nd.val = val;
    }
    debug_assert_eq!(out.len(), total);
    out
}

impl Seg<'_, &mut [f64]> {
    /// `x[p] −= t`.
    #[inline(always)]
    fn sub_at(&mut self, p: usize, t: f64) {
        if p < self.limit {
            self.own[p - self.base] -= t;
        } else {
            self.other[p - self.other_base] -= t;
        }
    }
}

impl Seg<'_, &[f64]> {
    /// `x[p]`.
    #[inline(always)]
    fn at(&self, p: usize) -> f64 {
        if p < self.limit {
            self.own[p - self.base]
        } else {
            self.other[p - self.other_base]
        }
    }
}

fn seg(own: &mut [f64], base: usize, limit: usize) -> Seg<'_, &mut [f64]> {
    Seg {
        own,
        base,
        limit,
        other: &mut [],
        other_base: limit,
    }
}

fn seg_r(own: &mut [f64], base: usize, limit: usize) -> Seg<'_, &[f64]> {
    Seg {
        own,
        base,
        limit,
        other: &[],
        other_base: limit,
    }
}

/// The supernode holding each column, the parent of each supernode in the elimination tree
/// (`usize::MAX` for a root), then the split: walk down from the root while a supernode has
/// one child; at the first with several, give its first children to one half and the rest to
/// the other, as evenly (by stored values) as possible.
fn find_split(f: &Factor, n: usize) -> Option<Split> {
    let ns = f.nodes.len();
    if ns < 3 {
        return None;
    }
    let mut node_of = vec![0usize; n];
    for (s, nd) in f.nodes.iter().enumerate() {
        node_of[nd.start..nd.start + nd.ncols].fill(s);
    }
    let parent: Vec<usize> = f
        .nodes
        .iter()
        .map(|nd| {
            f.pattern[nd.pat..nd.pat + nd.rows]
                .iter()
                .min()
                .map_or(usize::MAX, |&r| node_of[r as usize])
        })
        .collect();
    let weight: Vec<usize> = f.nodes.iter().map(|s| s.ncols * (s.ncols + s.rows)).collect();
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); ns + 1];
    for (s, &p) in parent.iter().enumerate() {
        children[if p == usize::MAX { ns } else { p }].push(s);
    }
    // Subtree weights (children come before parents in faer's order).
    let mut sub = weight.clone();
    sub.push(0);
    for s in 0..ns {
        let p = if parent[s] == usize::MAX { ns } else { parent[s] };
        if p <= s && p != ns {
            return None;
        }
        sub[p] += sub[s];
    }
    // Descend from the (virtual) root while there is one child.
    let mut top = ns;
    while children[top].len() == 1 {
        top = children[top][0];
    }
    let kids = &children[top];
    if kids.len() < 2 {
        return None;
    }
    let total: usize = kids.iter().map(|&k| sub[k]).sum();
    let (mut acc, mut cut) = (0, 0);
    for (i, &k) in kids.iter().enumerate().take(kids.len() - 1) {
        acc += sub[k];
        cut = i + 1;
        if 2 * acc >= total {
            break;
        }
    }
    // Halves as supernode ranges: up to the last of the first `cut` children, then up to the
    // last of the others.
    let a = kids[cut - 1] + 1;
    let b = kids[kids.len() - 1] + 1;
    let c1 = f.nodes[a].start;
    let c2 = if b < ns { f.nodes[b].start } else { n };
    let split = Split { a, b, c1, c2 };
    // Both halves must hold real work, and the first must not touch the second.
    let (wa, wb): (usize, usize) = (weight[..a].iter().sum(), weight[a..b].iter().sum());
    if wa == 0 || wb == 0 || 4 * wa.min(wb) < wa.max(wb) {
        return None;
    }
    let independent = f.nodes[..a].iter().all(|nd| {
        f.pattern[nd.pat..nd.pat + nd.rows]
            .iter()
            .all(|&r| (r as usize) < c1 || (r as usize) >= c2)
    });
    independent.then_some(split)
}

const FORWARD: u64 = 1;
const BACKWARD: u64 = 2;
const EXIT: u64 = 3;

/// State shared with the worker thread. `x` and `spill` are written by one thread at a time
/// or in disjoint parts (see [`SecondCore::solve`]); the atomics order the hand-overs.
struct Shared {
    factor: Arc<Factor>,
    split: Split,
    n: usize,
    /// The permuted right-hand side: `x_ptr` points into `_x`, whose buffer is never touched
    /// through the `Vec` again (all access goes through the pointer, in the parts above).
    _x: Vec<f64>,
    x_ptr: *mut f64,
    /// The worker's forward updates of rows `c2..n` (added in by the calling thread).
    spill: UnsafeCell<Vec<f64>>,
    tmp: UnsafeCell<Vec<f64>>,
    /// `sequence << 2 | phase` of the last command, and the last sequence done.
    command: AtomicU64,
    done: AtomicU64,
    parked: AtomicBool,
}

// SAFETY: the cells are accessed as described on `Shared`: between a command and its `done`,
// the worker touches only `x[0..c1]`, `spill`, `tmp` and reads `x[c2..n]` (backward); the calling
// thread touches only `x[c1..n]` (forward) or `x[c1..c2]` and reads `x[c2..n]` (backward).
unsafe impl Sync for Shared {}
// SAFETY: `x_ptr` points into the buffer `Shared` owns.
unsafe impl Send for Shared {}

struct SecondCore {
    shared: Arc<Shared>,
    sequence: u64,
    worker: Option<std::thread::JoinHandle<()>>,
}

/// How long the worker spins for the next command before it parks.
const SPIN: Duration = Duration::from_micros(200);

impl SecondCore {
    fn start(factor: Arc<Factor>, split: Split, n: usize, max_rows: usize) -> Option<Self> {
        let mut x = vec![0.0; n];
        let x_ptr = x.as_mut_ptr();
        let shared = Arc::new(Shared {
            factor,
            split,
            n,
            _x: x,
            x_ptr,
            spill: UnsafeCell::new(vec![0.0; n - split.c2]),
            tmp: UnsafeCell::new(vec![0.0; max_rows]),
            command: AtomicU64::new(0),
            done: AtomicU64::new(0),
            parked: AtomicBool::new(false),
        });
        let s = shared.clone();
        let worker = std::thread::Builder::new()
            .name("substep-solve".into())
            .spawn(move || worker_loop(&s))
            .ok()?;
        Some(Self {
            shared,
            sequence: 0,
            worker: Some(worker),
        })
    }

    fn command(&mut self, phase: u64) {
        self.sequence += 1;
        self.shared.command.store(self.sequence << 2 | phase, Ordering::SeqCst);
        if self.shared.parked.load(Ordering::SeqCst)
            && let Some(w) = &self.worker
        {
            w.thread().unpark();
        }
    }

    fn wait(&self) {
        let mut spins = 0u32;
        while self.shared.done.load(Ordering::Acquire) != self.sequence {
            std::hint::spin_loop();
            spins = spins.wrapping_add(1);
            if spins.is_multiple_of(4096) {
                // The worker may have been descheduled (a loaded machine): give it the core.
                std::thread::yield_now();
                // A worker that ended cannot finish the sweep: fail loudly rather than hang.
                assert!(
                    self.worker.as_ref().is_some_and(|w| !w.is_finished()),
                    "the sparse-solve worker thread ended during a solve"
                );
            }
        }
    }

    fn solve(&mut self, fwd: &[u32], x: &mut [f64], tmp: &mut [f64]) {
        let sh = self.shared.clone();
        let Split { a, b, c1, c2 } = sh.split;
        let (n, f) = (sh.n, &*sh.factor);
        let top = b..f.nodes.len();
        let ptr = sh.x_ptr;
        {
            // SAFETY: the worker is idle (its last command is done), so this thread owns `x`.
            let w = unsafe { std::slice::from_raw_parts_mut(ptr, n) };
            for (wi, &p) in w.iter_mut().zip(fwd) {
                *wi = x[p as usize];
            }
        }
        self.command(FORWARD);
        {
            // SAFETY: the worker uses x[0..c1] only; this thread x[c1..n].
            let mine = unsafe { std::slice::from_raw_parts_mut(ptr.add(c1), n - c1) };
            forward(f, a..b, seg(mine, c1, n), tmp);
        }
        self.wait();
        // SAFETY: the worker is idle again.
        let (w, spill) = unsafe { (std::slice::from_raw_parts_mut(ptr, n), &*sh.spill.get()) };
        for (wi, s) in w[c2..].iter_mut().zip(spill) {
            *wi += s;
        }
        forward(f, top.clone(), seg(w, 0, n), tmp);
        backward(f, top, seg_r(w, 0, n), tmp);
        self.command(BACKWARD);
        {
            // SAFETY: the worker writes x[0..c1] and reads x[c2..n]; this thread writes
            // x[c1..c2] and reads x[c2..n].
            let mine = unsafe { std::slice::from_raw_parts_mut(ptr.add(c1), c2 - c1) };
            let shared_top = unsafe { std::slice::from_raw_parts(ptr.add(c2), n - c2) };
            let s = Seg {
                own: mine,
                base: c1,
                limit: c2,
                other: shared_top,
                other_base: c2,
            };
            backward(f, a..b, s, tmp);
        }
        self.wait();
        // SAFETY: the worker is idle again.
        let w = unsafe { std::slice::from_raw_parts(ptr, n) };
        for (wi, &p) in w.iter().zip(fwd) {
            x[p as usize] = *wi;
        }
    }
}

impl Drop for SecondCore {
    fn drop(&mut self) {
        self.command(EXIT);
        if let Some(w) = self.worker.take() {
            w.thread().unpark();
            let _ = w.join();
        }
    }
}

fn worker_loop(sh: &Shared) {
    let mut seen = 0u64;
    loop {
        let started = Instant::now();
        let mut spins = 0u32;
        let cmd = loop {
            let c = sh.command.load(Ordering::SeqCst);
            if c >> 2 != seen {
                break c;
            }
            std::hint::spin_loop();
            spins = spins.wrapping_add(1);
            if spins.is_multiple_of(1024) && started.elapsed() > SPIN {
                sh.parked.store(true, Ordering::SeqCst);
                if sh.command.load(Ordering::SeqCst) >> 2 == seen {
                    std::thread::park();
                }
                sh.parked.store(false, Ordering::SeqCst);
            }
        };
        seen = cmd >> 2;
        let Split { a, c1, c2, .. } = sh.split;
        let (n, f) = (sh.n, &*sh.factor);
        let ptr = sh.x_ptr;
        // SAFETY: see `Shared`.
        let tmp = unsafe { &mut *sh.tmp.get() };
        match cmd & 3 {
            FORWARD => {
                let spill = unsafe { &mut *sh.spill.get() };
                spill.fill(0.0);
                let mine = unsafe { std::slice::from_raw_parts_mut(ptr, c1) };
                let s = Seg {
                    own: mine,
                    base: 0,
                    limit: c1,
                    other: &mut spill[..],
                    other_base: c2,
                };
                forward(f, 0..a, s, tmp);
            }
            BACKWARD => {
                let mine = unsafe { std::slice::from_raw_parts_mut(ptr, c1) };
                let top = unsafe { std::slice::from_raw_parts(ptr.add(c2), n - c2) };
                let s = Seg {
                    own: mine,
                    base: 0,
                    limit: c1,
                    other: top,
                    other_base: c2,
                };
                backward(f, 0..a, s, tmp);
            }
            _ => {
                sh.done.store(seen, Ordering::Release);
                return;
            }
        }
        sh.done.store(seen, Ordering::Release);
    }
}

fn forward(f: &Factor, nodes: std::ops::Range<usize>, mut s: Seg<'_, &mut [f64]>, tmp: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if f.use_fma {
        // SAFETY: `use_fma` is true only when the CPU reports AVX2 and FMA.
        unsafe { forward_fma(f, nodes, &mut s, tmp) };
        return;
    }
    forward_sweep::<false>(f, nodes, &mut s, tmp);
}

fn backward(f: &Factor, nodes: std::ops::Range<usize>, mut s: Seg<'_, &[f64]>, tmp: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if f.use_fma {
        // SAFETY: as in `forward`.
        unsafe { backward_fma(f, nodes, &mut s, tmp) };
        return;
    }
    backward_sweep::<false>(f, nodes, &mut s, tmp);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn forward_fma(f: &Factor, nodes: std::ops::Range<usize>, s: &mut Seg<'_, &mut [f64]>, tmp: &mut [f64]) {
    forward_sweep::<true>(f, nodes, s, tmp);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn backward_fma(f: &Factor, nodes: std::ops::Range<usize>, s: &mut Seg<'_, &[f64]>, tmp: &mut [f64]) {
    backward_sweep::<true>(f, nodes, s, tmp);
}

#[inline(always)]
fn forward_sweep<const FMA: bool>(
    f: &Factor,
    nodes: std::ops::Range<usize>,
    s: &mut Seg<'_, &mut [f64]>,
    tmp: &mut [f64],
) {
    for nd in &f.nodes[nodes] {
        forward_node::<FMA>(
            nd,
            &f.pattern[nd.pat..nd.pat + nd.rows],
            &f.values,
            s,
            &mut tmp[..nd.rows],
        );
    }
}

#[inline(always)]
fn backward_sweep<const FMA: bool>(
    f: &Factor,
    nodes: std::ops::Range<usize>,
    s: &mut Seg<'_, &[f64]>,
    tmp: &mut [f64],
) {
    for nd in f.nodes[nodes].iter().rev() {
        backward_node::<FMA>(
            nd,
            &f.pattern[nd.pat..nd.pat + nd.rows],
            &f.values,
            s,
            &mut tmp[..nd.rows],
        );
    }
}

/// `f64` values in memory aligned to 2 MiB and, on Linux, advised to transparent huge pages:
/// a solve streams tens of megabytes, and with 4 KiB pages every page is a TLB miss that also
/// stops the hardware prefetcher.
pub(crate) struct HugeBuf {
    ptr: std::ptr::NonNull<f64>,
    len: usize,
    layout: std::alloc::Layout,
}

// SAFETY: `HugeBuf` owns its allocation like a `Box<[f64]>`.
unsafe impl Send for HugeBuf {}
unsafe impl Sync for HugeBuf {}

impl HugeBuf {
    const HUGE: usize = 2 << 20;

    pub(crate) fn from_slice(v: &[f64]) -> Self {
        // Small factors stay in the cache anyway: no 2 MiB rounding for them.
        let huge = v.len() * 8 >= 2 * Self::HUGE;
        let align = if huge { Self::HUGE } else { 64 };
        let bytes = (v.len() * 8).max(8).next_multiple_of(align);
        let layout = std::alloc::Layout::from_size_align(bytes, align).expect("valid layout");
        // SAFETY: `layout` has a non-zero size.
        let raw = unsafe { std::alloc::alloc(layout) } as *mut f64;
        let Some(ptr) = std::ptr::NonNull::new(raw) else {
            std::alloc::handle_alloc_error(layout);
        };
        #[cfg(target_os = "linux")]
        if huge {
            // SAFETY: the range is the allocation just made; the advice only changes paging.
            unsafe {
                libc::madvise(raw as *mut libc::c_void, bytes, libc::MADV_HUGEPAGE);
            }
        }
        // SAFETY: the allocation holds at least `v.len()` values and does not overlap `v`.
        unsafe { std::ptr::copy_nonoverlapping(v.as_ptr(), raw, v.len()) };
        Self {
            ptr,
            len: v.len(),
            layout,
        }
    }
}

impl std::ops::Deref for HugeBuf {
    type Target = [f64];
    fn deref(&self) -> &[f64] {
        // SAFETY: `len` values were initialised in `from_slice`.
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }
}

impl Drop for HugeBuf {
    fn drop(&mut self) {
        // SAFETY: allocated in `from_slice` with this layout.
        unsafe { std::alloc::dealloc(self.ptr.as_ptr() as *mut u8, self.layout) };
    }
}

fn has_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `a · b + c`, fused when `FMA`.
#[inline(always)]
fn madd<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FMA { a.mul_add(b, c) } else { a * b + c }
}

/// `y = L_diag⁻¹ w_s`, then `w_pattern −= L_off y` (layout of [`pack`]).
#[inline(always)]
fn forward_node<const FMA: bool>(s: &Node, pat: &[u32], values: &[f64], w: &mut Seg<'_, &mut [f64]>, tmp: &mut [f64]) {
    let (nc, r) = (s.ncols, s.rows);
    let diag_len = nc * (nc + 1) / 2;
    let diag = &values[s.val..s.val + diag_len];
    let top = &mut w.own[s.start - w.base..s.start - w.base + nc];
    let mut p = 0;
    for j in 0..nc {
        let col = &diag[p..p + nc - j];
        let yj = top[j] * col[0];
        top[j] = yj;
        for (t, &l) in top[j + 1..].iter_mut().zip(&col[1..]) {
            *t = madd::<FMA>(-l, yj, *t);
        }
        p += nc - j;
    }
    if r == 0 {
        return;
    }
    let off = &values[s.val + diag_len..s.val + diag_len + nc * r];
    if nc <= 4 {
        // One group (a frame node's three DOFs are the common supernode): each row's update
        // straight into `w`, without the pass through `tmp` (same arithmetic, same order).
        let y = &top[..nc];
        let mut yw = [0.0; 4];
        yw[..nc].copy_from_slice(y);
        match nc {
            4 => forward_direct::<FMA, 4>(off, &yw, pat, w),
            3 => forward_direct::<FMA, 3>(off, &yw, pat, w),
            2 => forward_direct::<FMA, 2>(off, &yw, pat, w),
            _ => forward_direct::<FMA, 1>(off, &yw, pat, w),
        }
        return;
    }
    // tmp = L_off y, one group of four columns per pass, each row's four values adjacent.
    let tmp = &mut tmp[..r];
    tmp.fill(0.0);
    for g in (0..nc).step_by(4) {
        let width = (nc - g).min(4);
        let block = &off[g * r..(g + width) * r];
        let y = &top[g..g + width];
        // The width is a constant in each arm, so the per-row loop is unrolled (frames have
        // three DOFs per node: groups of one to three columns are common, not a remainder).
        match width {
            4 => forward_group::<FMA, 4>(block, y, tmp),
            3 => forward_group::<FMA, 3>(block, y, tmp),
            2 => forward_group::<FMA, 2>(block, y, tmp),
            _ => forward_group::<FMA, 1>(block, y, tmp),
        }
    }
    for (&p, &t) in pat.iter().zip(tmp.iter()) {
        w.sub_at(p as usize, t);
    }
}

/// `w_s −= L_offᵀ w_pattern`, then `w_s = L_diag⁻ᵀ w_s` (layout of [`pack`]).
#[inline(always)]
fn backward_node<const FMA: bool>(s: &Node, pat: &[u32], values: &[f64], w: &mut Seg<'_, &[f64]>, tmp: &mut [f64]) {
    let (nc, r) = (s.ncols, s.rows);
    let diag_len = nc * (nc + 1) / 2;
    let at = s.start - w.base;
    if r > 0 && nc <= 4 {
        // One group: gather `w` straight into the dot products (as in `forward_node`).
        let off = &values[s.val + diag_len..s.val + diag_len + nc * r];
        let acc = match nc {
            4 => backward_direct::<FMA, 4>(off, pat, w),
            3 => backward_direct::<FMA, 3>(off, pat, w),
            2 => backward_direct::<FMA, 2>(off, pat, w),
            _ => backward_direct::<FMA, 1>(off, pat, w),
        };
        for (l, a) in acc.iter().take(nc).enumerate() {
            w.own[at + l] -= a;
        }
    } else if r > 0 {
        let tmp = &mut tmp[..r];
        for (t, &p) in tmp.iter_mut().zip(pat) {
            *t = w.at(p as usize);
        }
        let off = &values[s.val + diag_len..s.val + diag_len + nc * r];
        for g in (0..nc).step_by(4) {
            let width = (nc - g).min(4);
            let block = &off[g * r..(g + width) * r];
            let acc = match width {
                4 => backward_group::<FMA, 4>(block, tmp),
                3 => backward_group::<FMA, 3>(block, tmp),
                2 => backward_group::<FMA, 2>(block, tmp),
                _ => backward_group::<FMA, 1>(block, tmp),
            };
            for (l, a) in acc.iter().take(width).enumerate() {
                w.own[at + g + l] -= a;
            }
        }
    }
    let diag = &values[s.val..s.val + diag_len];
    let top = &mut w.own[at..at + nc];
    for j in (0..nc).rev() {
        let p = j * nc - j * j.saturating_sub(1) / 2;
        let col = &diag[p..p + nc - j];
        let d = dot::<FMA>(&col[1..], &top[j + 1..]);
        top[j] = (top[j] - d) * col[0];
    }
}

/// `w[pat[k]] −= block_k · y` for a supernode of `W ≤ 4` columns (one group), the dot products
/// formed by [`row_dot`] from zero, as [`forward_group`] does for the first group.
#[inline(always)]
fn forward_direct<const FMA: bool, const W: usize>(
    block: &[f64],
    y: &[f64; 4],
    pat: &[u32],
    w: &mut Seg<'_, &mut [f64]>,
) {
    for (&p, v) in pat.iter().zip(block.chunks_exact(W)) {
        w.sub_at(p as usize, row_dot::<FMA, W>(v, y, 0.0));
    }
}

/// `blockᵀ · w[pat]` for a supernode of `W ≤ 4` columns, gathered row by row, with the even
/// and odd partial sums of [`backward_group`].
#[inline(always)]
fn backward_direct<const FMA: bool, const W: usize>(block: &[f64], pat: &[u32], w: &Seg<'_, &[f64]>) -> [f64; 4] {
    backward_rows::<FMA, W>(block, pat.len(), |k| w.at(pat[k] as usize))
}

/// `tmp += block · y` for a group of `W` columns stored row by row.
#[inline(always)]
fn forward_group<const FMA: bool, const W: usize>(block: &[f64], y: &[f64], tmp: &mut [f64]) {
    let mut yw = [0.0; W];
    yw.copy_from_slice(&y[..W]);
    for (t, v) in tmp.iter_mut().zip(block.chunks_exact(W)) {
        *t = row_dot::<FMA, W>(v, &yw, *t);
    }
}

/// `init + v · y` over `W ≤ 4` values.
#[inline(always)]
fn row_dot<const FMA: bool, const W: usize>(v: &[f64], y: &[f64], init: f64) -> f64 {
    if W == 4 {
        // Two short chains instead of one of four.
        let a = madd::<FMA>(v[1], y[1], v[0] * y[0]);
        let b = madd::<FMA>(v[3], y[3], v[2] * y[2]);
        init + (a + b)
    } else {
        let mut acc = init;
        for l in 0..W {
            acc = madd::<FMA>(v[l], y[l], acc);
        }
        acc
    }
}

/// `blockᵀ · tmp` for a group of `W ≤ 4` columns stored row by row (lanes `W..` are zero);
/// even and odd rows in separate partial sums, so consecutive rows do not wait on each
/// other's additions.
#[inline(always)]
fn backward_group<const FMA: bool, const W: usize>(block: &[f64], tmp: &[f64]) -> [f64; 4] {
    backward_rows::<FMA, W>(block, tmp.len(), |k| tmp[k])
}

/// `blockᵀ · x` over `r` rows, `x_k = x(k)`, with the partial sums of [`backward_group`].
#[inline(always)]
fn backward_rows<const FMA: bool, const W: usize>(block: &[f64], r: usize, x: impl Fn(usize) -> f64) -> [f64; 4] {
    let (mut even, mut odd) = ([0.0; W], [0.0; W]);
    for (i, v) in block[..2 * W * (r / 2)].chunks_exact(2 * W).enumerate() {
        let (t0, t1) = (x(2 * i), x(2 * i + 1));
        for l in 0..W {
            even[l] = madd::<FMA>(v[l], t0, even[l]);
            odd[l] = madd::<FMA>(v[W + l], t1, odd[l]);
        }
    }
    if r % 2 == 1 {
        let (v, t) = (&block[W * (r - 1)..W * r], x(r - 1));
        for l in 0..W {
            even[l] = madd::<FMA>(v[l], t, even[l]);
        }
    }
    let mut out = [0.0; 4];
    for l in 0..W {
        out[l] = even[l] + odd[l];
    }
    out
}

/// Dot product with eight partial sums (vectorises; the order is fixed, so reruns are
/// bit-identical).
#[inline(always)]
fn dot<const FMA: bool>(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut s = [0.0; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..8 {
            s[k] = madd::<FMA>(x[k], y[k], s[k]);
        }
    }
    let mut t = ((s[0] + s[4]) + (s[1] + s[5])) + ((s[2] + s[6]) + (s[3] + s[7]));
    for (x, y) in ra.iter().zip(rb) {
        t = madd::<FMA>(*x, *y, t);
    }
    t
}
