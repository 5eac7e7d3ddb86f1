//! An ASCII PLY reader for the examples (vertices and triangles; the shared meshes' format).
use glam::DVec3;

/// Reads the vertices and triangular faces of an ASCII PLY file.
pub fn read_ply(path: &str) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let text = std::fs::read_to_string(path).expect("read");
    let mut lines = text.lines();
    let (mut nv, mut nf) = (0usize, 0usize);
    for l in lines.by_ref() {
        if let Some(n) = l.strip_prefix("element vertex ") {
            nv = n.trim().parse().unwrap();
        }
        if let Some(n) = l.strip_prefix("element face ") {
            nf = n.trim().parse().unwrap();
        }
        if l == "end_header" {
            break;
        }
    }
    let mut numbers = || -> Vec<f64> {
        let line = lines.next().expect("fewer lines than the header says");
        line.split_whitespace()
            .map(|s| s.parse().unwrap())
            .collect()
    };
    let v = (0..nv)
        .map(|_| {
            let x = numbers();
            DVec3::new(x[0], x[1], x[2])
        })
        .collect();
    // A face line is its vertex count, then the indices.
    let f = (0..nf)
        .map(|_| {
            let x = numbers();
            [x[1], x[2], x[3]].map(|i| i as u32)
        })
        .collect();
    (v, f)
}
