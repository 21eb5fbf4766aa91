//! `cam.stl`: the part's mesh ([`crate::part::mesh`]) as binary STL.

use stl_io::Triangle;

/// Binary STL bytes.
pub fn stl_bytes(tris: &[Triangle]) -> Vec<u8> {
    let mut out = Vec::with_capacity(84 + 50 * tris.len());
    stl_io::write_stl(&mut out, tris.iter()).expect("writing to memory cannot fail");
    out
}
