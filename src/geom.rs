//! Plane geometry shared by the part outline, the meshes and the tool paths: points as
//! `[x, y]` in mm and the few vector operations on them.

/// A 2D point or vector (mm).
pub type P2 = [f64; 2];

/// a - b.
pub fn sub(a: P2, b: P2) -> P2 {
    [a[0] - b[0], a[1] - b[1]]
}

/// a + b.
pub fn add(a: P2, b: P2) -> P2 {
    [a[0] + b[0], a[1] + b[1]]
}

/// k a.
pub fn scale(a: P2, k: f64) -> P2 {
    [a[0] * k, a[1] * k]
}

/// a . b.
pub fn dot(a: P2, b: P2) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// The z component of a x b.
pub fn cross(a: P2, b: P2) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

/// |a|.
pub fn norm(a: P2) -> f64 {
    a[0].hypot(a[1])
}

/// |a - b|.
pub fn dist(a: P2, b: P2) -> f64 {
    norm(sub(a, b))
}

/// The left normal of a direction (rotated +90 deg).
pub fn left(t: P2) -> P2 {
    [-t[1], t[0]]
}

/// The right normal of a direction (rotated -90 deg).
pub fn right(t: P2) -> P2 {
    [t[1], -t[0]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vector_identities() {
        let (a, b) = ([3.0, 4.0], [1.0, -2.0]);
        assert_eq!(norm(a), 5.0);
        assert_eq!(dist(a, b), (4.0f64 + 36.0).sqrt());
        assert_eq!(dot(left(a), a), 0.0);
        assert_eq!(cross(a, left(a)), 25.0);
        assert_eq!(add(sub(a, b), b), a);
        assert_eq!(right(left(a)), a);
        assert_eq!(scale(a, 2.0), [6.0, 8.0]);
    }
}
