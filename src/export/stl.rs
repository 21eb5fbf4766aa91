//! `cam.stl`: the part's mesh ([`crate::part::mesh`]) as binary STL.

use stl_io::Triangle;

/// Binary STL bytes; the 80-byte header names the run (it never starts with "solid", which
/// would make readers take the file for ASCII STL).
pub fn stl_bytes(tris: &[Triangle], run_id: &str) -> Vec<u8> {
    let mut out = Vec::with_capacity(84 + 50 * tris.len());
    // Writing into a Vec cannot fail; an error would leave the bytes written so far.
    let _ = stl_io::write_stl(&mut out, tris.iter());
    let header = format!("camspring run {run_id}");
    let n = header.len().min(80);
    if out.len() >= 80 {
        out[..80].fill(b' ');
        out[..n].copy_from_slice(&header.as_bytes()[..n]);
    }
    out
}
