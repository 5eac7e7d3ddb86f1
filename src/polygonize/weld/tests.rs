use super::*;
use crate::field::analytic::Sphere;
use crate::field::Field;
use crate::mesh::Mesh;
use crate::polygonize::{octree, polygonize, Method, Settings};

/// `field` polygonized over `lattice` by `method`, with the vertices' edge keys.
fn keyed<F: Field>(field: &F, lattice: &Lattice, mut method: Method) -> (Mesh, Vec<u64>) {
    match &mut method {
        Method::Dense(s) | Method::Sparse(s) => s.keys = true,
        Method::Octree(o) => o.common.keys = true,
        Method::Tracking(t) => t.common.keys = true,
    }
    let p = polygonize(field, lattice, &method).unwrap();
    (p.mesh, p.keys.unwrap())
}

/// Bit patterns of a position: equal exactly for equal coordinates.
type Bits = [u64; 3];

fn bits(p: DVec3) -> Bits {
    p.to_array().map(f64::to_bits)
}

/// `|x| + |y| + |z| − 0.75`: zero at many lattice points of a lattice of cells of 1/8,
/// where up to six crossed edges give one position.
struct Octahedron;

impl Field for Octahedron {
    fn value(&self, p: DVec3) -> f64 {
        p.x.abs() + p.y.abs() + p.z.abs() - 0.75
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        DVec3::new(p.x.signum(), p.y.signum(), p.z.signum())
    }
}

/// Positions of each triangle's corners, bit for bit, sorted: equal for equal meshes
/// whatever their numbering.
fn triangles(v: &[DVec3], f: impl Iterator<Item = [usize; 3]>) -> Vec<[Bits; 3]> {
    let mut t: Vec<[Bits; 3]> = f.map(|t| t.map(|i| bits(v[i]))).collect();
    for t in &mut t {
        let m = (0..3).min_by_key(|&k| t[k]).unwrap();
        t.rotate_left(m);
    }
    t.sort_unstable();
    t
}

fn tiles_of(lattice: &Lattice, tile: u32) -> Vec<(Lattice, [[u32; 3]; 2])> {
    let starts = |n: u32| {
        (0..n)
            .step_by(tile as usize)
            .map(move |s| (s, (s + tile).min(n)))
    };
    let [nx, ny, nz] = lattice.cells();
    let mut out = Vec::new();
    for (z0, z1) in starts(nz) {
        for (y0, y1) in starts(ny) {
            for (x0, x1) in starts(nx) {
                let w = [[x0, y0, z0], [x1, y1, z1]];
                out.push((lattice.window(w[0], w[1]).unwrap(), w));
            }
        }
    }
    out
}

/// A tile's mesh, its faces and its boundary vertices with their edge keys.
type TileMesh = (Mesh, Vec<[u32; 3]>, (Vec<u32>, Vec<u64>), [[u32; 3]; 2]);

/// Polygonizes every tile of `tile` cells with `polygonize` (a mesh and its edge keys).
fn tile_meshes(
    lattice: &Lattice,
    tile: u32,
    polygonize: impl Fn(&Lattice) -> (Mesh, Vec<u64>),
) -> Vec<TileMesh> {
    tiles_of(lattice, tile)
        .into_iter()
        .map(|(l, w)| {
            let (m, keys) = polygonize(&l);
            assert_eq!(keys.len(), m.vertices.len());
            let f = m.triangles.clone();
            (m, f, boundary_edges(&keys, w), w)
        })
        .collect()
}

fn as_tiles(meshes: &[TileMesh]) -> Vec<Tile<'_>> {
    meshes
        .iter()
        .map(|(m, f, (b, k), w)| Tile {
            window: *w,
            vertices: &m.vertices,
            faces: f,
            normals: &m.normals,
            boundary: b,
            keys: k,
        })
        .collect()
}

/// The welded mesh is `whole`: the same number of vertices, the same triangles and normals
/// bit for bit, the same Euler characteristic.
fn assert_whole(welded: &Welded, whole: &Mesh) {
    assert_eq!(welded.vertices.len(), whole.vertices.len());
    assert_eq!(welded.faces.len(), whole.triangles.len());
    assert_eq!(
        triangles(
            &welded.vertices,
            welded.faces.iter().map(|t| t.map(|i| i as usize))
        ),
        triangles(
            &whole.vertices,
            whole.triangles.iter().map(|t| t.map(|i| i as usize))
        )
    );
    let normals = |v: &[DVec3], n: &[DVec3]| {
        let mut p: Vec<(Bits, Bits)> = v.iter().zip(n).map(|(&a, &b)| (bits(a), bits(b))).collect();
        p.sort_unstable();
        p
    };
    assert_eq!(
        normals(&welded.vertices, &welded.normals),
        normals(&whole.vertices, &whole.normals)
    );
    let mesh = Mesh {
        vertices: welded.vertices.clone(),
        triangles: welded.faces.iter().map(|t| t.map(|i| i as u32)).collect(),
        normals: Vec::new(),
    };
    assert_eq!(mesh.euler_characteristic(), whole.euler_characteristic());
    assert_eq!(mesh.is_closed_oriented(), whole.is_closed_oriented());
}

/// Tiles of a sphere, welded, give the whole lattice's mesh: the same triangles and
/// normals bit for bit, the same number of vertices, tile after tile.
#[test]
fn welded_tiles_are_the_whole_mesh() {
    let sphere = Sphere {
        center: DVec3::new(0.03, -0.05, 0.02),
        radius: 0.7,
    };
    let lattice =
        Lattice::new(DVec3::splat(-1.0), DVec3::new(1.0, 0.9, 0.8), [23, 19, 17]).unwrap();
    let settings = Settings::default();
    let whole = polygonize(&sphere, &lattice, &Method::Dense(settings))
        .unwrap()
        .mesh;
    let meshes = tile_meshes(&lattice, 5, |l| keyed(&sphere, l, Method::Dense(settings)));
    let welded = weld(&as_tiles(&meshes), &lattice).unwrap();
    assert_whole(&welded, &whole);
    // The first tile's vertices come first, in their order.
    let first = &meshes[0].0.vertices;
    assert_eq!(&welded.vertices[..first.len()], &first[..]);
}

/// Where the field is zero at lattice points on tile faces, edges and corners (several
/// vertices at one position in a tile and on one machine), the weld joins each vertex to
/// the one of its own edge: the whole mesh, vertex for vertex, for dense and octree tiles.
#[test]
fn zeros_at_lattice_points_weld_to_the_whole_mesh() {
    let lattice = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 16).unwrap();
    let settings = Settings::default();
    let (whole, keys) = keyed(&Octahedron, &lattice, Method::Dense(settings));
    // One vertex per crossed edge: several at one position, distinct keys.
    let mut at = whole.vertices.iter().map(|&p| bits(p)).collect::<Vec<_>>();
    at.sort_unstable();
    at.dedup();
    assert!(at.len() < whole.vertices.len());
    let mut distinct = keys.clone();
    distinct.sort_unstable();
    distinct.dedup();
    assert_eq!(distinct.len(), whole.vertices.len());
    assert!(whole.is_closed_oriented());
    let octree_settings = octree::OctreeSettings::default();
    let whole_octree = polygonize(&Octahedron, &lattice, &Method::Octree(octree_settings))
        .unwrap()
        .mesh;
    for tile in [2, 3, 5, 16] {
        let meshes = tile_meshes(&lattice, tile, |l| {
            keyed(&Octahedron, l, Method::Dense(settings))
        });
        assert_whole(&weld(&as_tiles(&meshes), &lattice).unwrap(), &whole);
        let meshes = tile_meshes(&lattice, tile, |l| {
            keyed(&Octahedron, l, Method::Octree(octree_settings))
        });
        assert_whole(&weld(&as_tiles(&meshes), &lattice).unwrap(), &whole_octree);
    }
}

/// A sphere's dense tiles of `tile` cells on a lattice of 18³ cells over [-1, 1]³.
fn sphere_tiles(tile: u32) -> (Lattice, Vec<TileMesh>) {
    let sphere = Sphere {
        center: DVec3::new(0.03, -0.05, 0.02),
        radius: 0.7,
    };
    let lattice = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 18).unwrap();
    let settings = Settings::default();
    let meshes = tile_meshes(&lattice, tile, |l| {
        keyed(&sphere, l, Method::Dense(settings))
    });
    (lattice, meshes)
}

/// A streamed weld told of one tile and given them all (its rows grow past every
/// estimate) makes the arrays of a weld told of all; a tile refused leaves it unchanged.
#[test]
fn a_streamed_weld_grows_past_its_estimate_and_survives_a_refused_tile() {
    let (lattice, meshes) = sphere_tiles(4);
    let tiles = as_tiles(&meshes);
    let mut stream = StreamedWeld::new(1, None);
    let mut seen = std::collections::HashSet::new();
    let mut refused = 0;
    for tile in &tiles {
        let moved: Vec<DVec3> = tile.vertices.iter().map(|&p| p + DVec3::X).collect();
        let bad = Tile {
            vertices: &moved,
            ..*tile
        };
        // Moved, a vertex of an edge an earlier tile has is at other coordinates.
        if tile.keys.iter().any(|k| seen.contains(k)) {
            let before = (stream.added(), stream.vertices());
            assert!(stream.add(&bad, &lattice).is_err());
            assert_eq!((stream.added(), stream.vertices()), before);
            refused += 1;
        }
        stream.add(tile, &lattice).unwrap();
        seen.extend(tile.keys.iter().copied());
    }
    assert!(refused > 10);
    assert_eq!(stream.finish(), weld(&tiles, &lattice).unwrap());
}

/// A weld with a memory limit refuses the tile that would take the welded mesh's rows over
/// it, naming `memory_limit`, and is unchanged; the tiles before it are welded as without a
/// limit.
#[test]
fn a_streamed_weld_refuses_a_tile_over_its_memory_limit() {
    let (lattice, meshes) = sphere_tiles(6);
    let tiles = as_tiles(&meshes);
    let whole = weld(&tiles, &lattice).unwrap();
    let bytes = (whole.vertices.len() * 48 + whole.faces.len() * 24) as u64;
    let mut unlimited = StreamedWeld::new(tiles.len(), None);
    let mut stream = StreamedWeld::new(tiles.len(), None).with_memory_limit(bytes / 2);
    let mut refused = None;
    for (t, tile) in tiles.iter().enumerate() {
        let before = (stream.added(), stream.vertices());
        match stream.add(tile, &lattice) {
            Ok(()) => unlimited.add(tile, &lattice).unwrap(),
            Err(Error::InvalidArgument { name, reason }) => {
                assert_eq!(name, "memory_limit");
                assert!(reason.contains("output=DIR"), "{reason}");
                assert_eq!((stream.added(), stream.vertices()), before);
                refused = Some(t);
                break;
            }
            Err(e) => panic!("{e:?}"),
        }
    }
    let t = refused.expect("half the whole mesh's bytes is reached before the last tile");
    assert!(t > 0);
    let (held, first) = (stream.finish(), unlimited.finish());
    assert_eq!(held, first);
    assert!((held.vertices.len() * 48 + held.faces.len() * 24) as u64 <= bytes / 2);
    // The whole mesh within a limit of its bytes.
    let mut exact = StreamedWeld::new(tiles.len(), None).with_memory_limit(bytes);
    for tile in &tiles {
        exact.add(tile, &lattice).unwrap();
    }
    assert_eq!(exact.finish(), whole);
}

/// Bad tiles are refused naming the argument at fault.
#[test]
fn bad_tiles_are_refused() {
    let lattice = Lattice::new(DVec3::ZERO, DVec3::ONE, [4, 4, 4]).unwrap();
    let v = [DVec3::ZERO, DVec3::X, DVec3::Y];
    let tile = |faces, normals, window| Tile {
        window,
        vertices: &v,
        faces,
        normals,
        boundary: &[],
        keys: &[],
    };
    let w = [[0, 0, 0], [4, 4, 4]];
    let name = |r: Result<Welded>| match r {
        Err(Error::InvalidArgument { name, .. }) => name,
        other => panic!("{other:?}"),
    };
    assert_eq!(name(weld(&[tile(&[[0, 1, 3]], &[], w)], &lattice)), "faces");
    assert_eq!(
        name(weld(&[tile(&[[0, 1, 2]], &v[..1], w)], &lattice)),
        "normals"
    );
    assert_eq!(
        name(weld(&[tile(&[], &[], [[0, 0, 0], [5, 4, 4]])], &lattice)),
        "window"
    );
    fn keyed<'a>(
        vertices: &'a [DVec3],
        boundary: &'a [u32],
        keys: &'a [u64],
        window: [[u32; 3]; 2],
    ) -> Tile<'a> {
        Tile {
            window,
            vertices,
            faces: &[],
            normals: &[],
            boundary,
            keys,
        }
    }
    let k = lattice.whole_edge_key([0, 0, 0], 0);
    let beyond = lattice.whole_edge_key([1, 0, 0], 0);
    let w1 = [[0, 0, 0], [1, 4, 4]];
    let name_of = |tiles: &[Tile]| name(weld(tiles, &lattice));
    let (one, two, three) = ([0u32], [0u32, 1], [3u32]);
    let (kk, k2) = ([k], [k, k]);
    assert_eq!(name_of(&[keyed(&v, &two, &kk, w)]), "keys");
    assert_eq!(name_of(&[keyed(&v, &three, &kk, w)]), "boundary");
    assert_eq!(name_of(&[keyed(&v, &one, &[beyond], w1)]), "keys");
    assert_eq!(name_of(&[keyed(&v, &two, &k2, w)]), "keys");
    // One edge at two positions in two tiles.
    let moved = [DVec3::X];
    assert_eq!(
        name_of(&[keyed(&v, &one, &kk, w1), keyed(&moved, &one, &kk, w1)]),
        "tiles"
    );
    assert_eq!(weld(&[], &lattice).unwrap(), Welded::default());
}

/// A plan made from the tiles' counts and boundary vertices alone, each tile's rows written
/// where it says into arrays of the whole mesh's size (last tile first, as workers finishing
/// in any order would), gives the arrays of the weld.
#[test]
fn planned_rows_written_in_any_order_are_the_weld() {
    let (lattice, meshes) = sphere_tiles(5);
    let tiles = as_tiles(&meshes);
    let whole = weld(&tiles, &lattice).unwrap();
    let mut plan = WeldPlan::new(Some(true));
    let plans: Vec<TilePlan> = tiles
        .iter()
        .map(|t| {
            let positions: Vec<DVec3> =
                t.boundary.iter().map(|&i| t.vertices[i as usize]).collect();
            let seams = Seams {
                window: t.window,
                vertices: t.vertices.len(),
                faces: t.faces.len(),
                normals: true,
                boundary: t.boundary,
                keys: t.keys,
                positions: &positions,
            };
            plan.add(&seams, &lattice).unwrap()
        })
        .collect();
    assert_eq!(
        (plan.vertices(), plan.faces()),
        (whole.vertices.len(), whole.faces.len())
    );
    assert!(plans.iter().any(|p| !p.joined.is_empty()));
    let mut v = vec![DVec3::NAN; plan.vertices()];
    let mut n = vec![DVec3::NAN; plan.vertices()];
    let mut f = vec![[-1i64; 3]; plan.faces()];
    for (t, p) in tiles.iter().zip(&plans).rev() {
        let (kept, nf) = (p.kept(), t.faces.len());
        let out = rows::Rows {
            vertices: rows::room(&mut v[p.first_vertex..p.first_vertex + kept]),
            normals: Some(rows::room(&mut n[p.first_vertex..p.first_vertex + kept])),
            faces: rows::room(&mut f[p.first_face..p.first_face + nf]),
        };
        rows::write(t.vertices, t.normals, t.faces, p, out).unwrap();
    }
    assert_eq!(
        Welded {
            vertices: v,
            faces: f,
            normals: n
        },
        whole
    );
    // Rows that do not fit the plan are refused.
    let (t, p) = (&tiles[1], &plans[1]);
    let mut short = vec![DVec3::ZERO; p.kept().saturating_sub(1)];
    let mut faces = vec![[0i64; 3]; t.faces.len()];
    let out = rows::Rows {
        vertices: rows::room(&mut short),
        normals: None,
        faces: rows::room(&mut faces),
    };
    assert!(rows::write(t.vertices, t.normals, t.faces, p, out).is_err());
    let bad = TilePlan {
        joined: vec![(0, p.first_vertex as Id)],
        ..p.clone()
    };
    assert!(rows::welded_index(&bad).is_err());
}
