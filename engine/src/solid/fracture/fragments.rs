//! Fragments: the sets of particles a chain of interacting pairs still
//! joins, found by union–find over the pairs of positive weight.

/// Labels `n` particles by fragment, given each particle's interacting
/// neighbours: returns the label of each (numbered from 0 in the order of
/// each fragment's lowest particle, so the labels do not depend on the
/// order pairs are visited in) and the number of fragments.
pub fn label<I: Iterator<Item = usize>>(
    n: usize,
    neighbours: impl Fn(usize) -> I,
) -> (Vec<u32>, u32) {
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for i in 0..n {
        for j in neighbours(i) {
            let (a, b) = (root(&mut parent, i), root(&mut parent, j));
            if a != b {
                // The lower index becomes the root.
                parent[a.max(b)] = a.min(b);
            }
        }
    }
    let mut labels = vec![u32::MAX; n];
    let mut count = 0u32;
    for i in 0..n {
        let r = root(&mut parent, i);
        if labels[r] == u32::MAX {
            labels[r] = count;
            count += 1;
        }
        labels[i] = labels[r];
    }
    (labels, count)
}
