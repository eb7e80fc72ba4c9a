//! Fragments: the sets of particles a chain of interacting pairs still
//! joins, kept up to date as cracks cut pairs.
//!
//! A body starts labelled by its connected parts, numbered in order of
//! their lowest particle (one part, 0, for any solid shape the scenes
//! build). Only a pair cut through can split a
//! fragment, and only when no other chain of pairs joins its two ends,
//! so each cut pair is checked by a search from both ends at once, one
//! particle at a time from each: while the ends are still joined (the
//! common case, around a crack's tip) the searches meet after a few
//! steps; when they are not, the search that runs out first has walked
//! the whole of the smaller part, which takes the next label. The cost
//! follows the particles near the cut, or the smaller part, never the
//! body.

use std::collections::{HashSet, VecDeque};

/// Labels `n` particles by connected part, given each particle's
/// interacting neighbours: parts numbered from 0 in order of their lowest
/// particle. Returns the labels and the number of parts.
pub fn label<I: Iterator<Item = usize>>(
    n: usize,
    neighbours: impl Fn(usize) -> I,
) -> (Vec<u32>, u32) {
    let mut labels = vec![u32::MAX; n];
    let mut count = 0;
    let mut queue = VecDeque::new();
    for start in 0..n {
        if labels[start] != u32::MAX {
            continue;
        }
        labels[start] = count;
        queue.push_back(start);
        while let Some(i) = queue.pop_front() {
            for j in neighbours(i) {
                if labels[j] == u32::MAX {
                    labels[j] = count;
                    queue.push_back(j);
                }
            }
        }
        count += 1;
    }
    (labels, count)
}

/// Splits off the part that cutting the pair `(a, b)` separated, if any:
/// `neighbours(i)` gives the particles `i` still interacts with (with
/// the pair already cut), `labels` each particle's fragment, `count` the
/// number of fragments, both updated when a new part is labelled.
pub fn split<I: Iterator<Item = usize>>(
    a: usize,
    b: usize,
    neighbours: impl Fn(usize) -> I,
    labels: &mut [u32],
    count: &mut u32,
) {
    if labels[a] != labels[b] {
        return;
    }
    let mut sides = [Search::new(a), Search::new(b)];
    loop {
        for k in 0..2 {
            let Some(i) = sides[k].queue.pop_front() else {
                // Side k is a whole part without the other end.
                for &i in &sides[k].seen {
                    labels[i] = *count;
                }
                *count += 1;
                return;
            };
            for j in neighbours(i) {
                if sides[1 - k].seen.contains(&j) {
                    return;
                }
                if sides[k].seen.insert(j) {
                    sides[k].queue.push_back(j);
                }
            }
        }
    }
}

/// One end's breadth-first search.
struct Search {
    queue: VecDeque<usize>,
    seen: HashSet<usize>,
}

impl Search {
    fn new(start: usize) -> Self {
        Self {
            queue: VecDeque::from([start]),
            seen: HashSet::from([start]),
        }
    }
}
