//! How a mesh's triangles connect: undirected edges with their use in each direction, and
//! union-find over vertex indices; what both defect finding and repair count with.

use std::collections::HashMap;

/// An undirected edge as (low vertex index, high vertex index).
pub(crate) type Edge = (u32, u32);
/// How often an edge is used low→high and high→low.
pub(crate) type EdgeUses = (usize, usize);

/// How often each undirected edge is used in each direction.
pub(crate) fn edge_uses(triangles: &[[u32; 3]]) -> HashMap<Edge, EdgeUses> {
    let mut count: HashMap<Edge, EdgeUses> = HashMap::new();
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if a < b {
                count.entry((a, b)).or_default().0 += 1;
            } else {
                count.entry((b, a)).or_default().1 += 1;
            }
        }
    }
    count
}

/// Union-find root of `i`, with path halving.
pub(crate) fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

/// Joins the sets of `a` and `b`.
pub(crate) fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        parent[ra.max(rb) as usize] = ra.min(rb);
    }
}
