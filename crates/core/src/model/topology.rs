//! Mesh connectivity: connected parts by union-find over triangle edges.

/// Union-find with path halving and union by size.
#[derive(Clone, Debug)]
pub struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    /// `n` singleton sets.
    pub fn new(n: usize) -> Self {
        Self {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }

    /// Representative of `x`'s set.
    pub fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let grand = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = grand;
            x = grand;
        }
        x
    }

    /// Merges the sets of `a` and `b`.
    pub fn union(&mut self, a: u32, b: u32) {
        let (mut a, mut b) = (self.find(a), self.find(b));
        if a == b {
            return;
        }
        if self.size[a as usize] < self.size[b as usize] {
            std::mem::swap(&mut a, &mut b);
        }
        self.parent[b as usize] = a;
        self.size[a as usize] += self.size[b as usize];
    }
}

/// Connected parts of a mesh: a dense label per vertex (0..count) in order of
/// first appearance, and the count. Vertices no triangle uses form their own parts.
pub fn connected_components(vertex_count: usize, triangles: &[[u32; 3]]) -> (usize, Vec<u32>) {
    let mut uf = UnionFind::new(vertex_count);
    for t in triangles {
        uf.union(t[0], t[1]);
        uf.union(t[1], t[2]);
    }
    let mut label_of_root = vec![u32::MAX; vertex_count];
    let mut labels = Vec::with_capacity(vertex_count);
    let mut count = 0u32;
    for v in 0..vertex_count as u32 {
        let root = uf.find(v) as usize;
        if label_of_root[root] == u32::MAX {
            label_of_root[root] = count;
            count += 1;
        }
        labels.push(label_of_root[root]);
    }
    (count as usize, labels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_triangles_sharing_nothing_are_two_parts() {
        let (n, labels) = connected_components(7, &[[0, 1, 2], [3, 4, 5], [2, 1, 0]]);
        assert_eq!(n, 3, "vertex 6 is alone");
        assert_eq!(labels[0], labels[2]);
        assert_ne!(labels[0], labels[3]);
    }
}
