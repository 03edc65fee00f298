//! SOAP against an independent transcription of the algorithm (naive f64 matrices,
//! Gram–Schmidt for the QR), by hand, and its checkpoint bytes.

use super::*;

/// SOAP written out with naive f64 matrices and modified Gram–Schmidt for the QR: an
/// independent transcription of the algorithm the module implements. `w` is `[r, c]`.
struct Reference {
    r: usize,
    c: usize,
    l: Vec<f64>,
    rr: Vec<f64>,
    ql: Vec<f64>,
    qr: Vec<f64>,
    m: Vec<f64>,
    v: Vec<f64>,
    t: usize,
}

pub(super) fn mm(a: &[f64], b: &[f64], n: usize, k: usize, m: usize) -> Vec<f64> {
    (0..n * m)
        .map(|ij| (0..k).map(|x| a[ij / m * k + x] * b[x * m + ij % m]).sum())
        .collect()
}

pub(super) fn tr(a: &[f64], n: usize, m: usize) -> Vec<f64> {
    (0..n * m).map(|ij| a[(ij % n) * m + ij / n]).collect()
}

fn gram_schmidt(a: &[f64], n: usize) -> Vec<f64> {
    let mut q = a.to_vec();
    for j in 0..n {
        for p in 0..j {
            let d: f64 = (0..n).map(|i| q[i * n + j] * q[i * n + p]).sum();
            for i in 0..n {
                q[i * n + j] -= d * q[i * n + p];
            }
        }
        let norm = (0..n).map(|i| q[i * n + j].powi(2)).sum::<f64>().sqrt();
        for i in 0..n {
            q[i * n + j] /= norm;
        }
    }
    q
}

impl Reference {
    fn step(&mut self, w: &mut [f64], g: &[f64], c: SoapConfig, lr: f64) {
        let (r, cc) = (self.r, self.c);
        let ggt = mm(g, &tr(g, r, cc), r, cc, r);
        let gtg = mm(&tr(g, r, cc), g, cc, r, cc);
        if self.l.is_empty() {
            // The bases are the state's, checked by the caller.
            self.l = ggt;
            self.rr = gtg;
            return;
        }
        self.t += 1;
        let rot =
            |x: &[f64], ql: &[f64], qr: &[f64]| mm(&mm(&tr(ql, r, r), x, r, r, cc), qr, r, cc, cc);
        let gr = rot(g, &self.ql, &self.qr);
        for k in 0..r * cc {
            self.m[k] = c.beta_1 * self.m[k] + (1.0 - c.beta_1) * g[k];
            self.v[k] = c.beta_2 * self.v[k] + (1.0 - c.beta_2) * gr[k] * gr[k];
        }
        let mr = rot(&self.m, &self.ql, &self.qr);
        let n: Vec<f64> = (0..r * cc)
            .map(|k| mr[k] / (self.v[k].sqrt() + c.epsilon))
            .collect();
        let back = mm(
            &mm(&self.ql, &n, r, r, cc),
            &tr(&self.qr, cc, cc),
            r,
            cc,
            cc,
        );
        let t = self.t as i32;
        let size = lr * (1.0 - c.beta_2.powi(t)).sqrt() / (1.0 - c.beta_1.powi(t));
        for k in 0..r * cc {
            w[k] -= size * back[k];
        }
        for (l, x) in self.l.iter_mut().zip(&ggt) {
            *l = c.beta_2 * *l + (1.0 - c.beta_2) * x;
        }
        for (rr, x) in self.rr.iter_mut().zip(&gtg) {
            *rr = c.beta_2 * *rr + (1.0 - c.beta_2) * x;
        }
        if self.t.is_multiple_of(c.every) {
            let sorted = |f: &[f64], q: &[f64], n: usize| {
                let fq = mm(f, q, n, n, n);
                let mut order: Vec<usize> = (0..n).collect();
                let est: Vec<f64> = (0..n)
                    .map(|j| (0..n).map(|i| q[i * n + j] * fq[i * n + j]).sum())
                    .collect();
                order.sort_by(|&a, &b| est[b].total_cmp(&est[a]));
                let qs: Vec<f64> = (0..n * n).map(|ij| q[ij / n * n + order[ij % n]]).collect();
                (gram_schmidt(&mm(f, &qs, n, n, n), n), order)
            };
            let (ql, ol) = sorted(&self.l, &self.ql, r);
            let (qr, or) = sorted(&self.rr, &self.qr, cc);
            let old = self.v.clone();
            for i in 0..r {
                for j in 0..cc {
                    self.v[i * cc + j] = old[ol[i] * cc + or[j]];
                }
            }
            (self.ql, self.qr) = (ql, qr);
        }
    }
}

#[test]
fn soap_follows_an_independent_transcription_for_30_steps() {
    let (r, c) = (3, 5);
    let config = SoapConfig {
        every: 4,
        ..SoapConfig::default()
    };
    let mut state = SoapState::<f64>::new(config, &[[r, c]]);
    let mut reference = Reference {
        r,
        c,
        l: vec![],
        rr: vec![],
        ql: vec![],
        qr: vec![],
        m: vec![0.0; r * c],
        v: vec![0.0; r * c],
        t: 0,
    };
    let mut p: Vec<f64> = (0..r * c + c).map(|k| (k as f64 * 0.37).sin()).collect();
    let mut w: Vec<f64> = p[..r * c].to_vec();
    for step in 0..30 {
        let g: Vec<f64> = (0..r * c + c)
            .map(|k| ((k * 13 + step * 7) as f64 * 0.91).cos() + 0.1 * (k % 3) as f64)
            .collect();
        state.update(&mut p, &g, 1e-2);
        reference.step(&mut w, &g[..r * c], config, 1e-2);
        if step == 0 {
            // GᵀG has a null space, where any orthonormal vectors are eigenvectors and
            // Adam's coordinates depend on the choice: the reference takes the bases
            // found here, once checked to be sorted eigenvectors.
            let m = &state.matrices[0];
            for (q, f, n) in [(&m.q_left, &reference.l, r), (&m.q_right, &reference.rr, c)] {
                let d = mm(&tr(q, n, n), &mm(f, q, n, n, n), n, n, n);
                let scale = (0..n).map(|i| d[i * n + i]).fold(0.0, f64::max);
                for i in 0..n {
                    for j in 0..n {
                        if i != j {
                            assert!(d[i * n + j].abs() < 1e-12 * scale, "QᵀFQ[{i},{j}]");
                        }
                    }
                    assert!(i == 0 || d[i * n + i] <= d[(i - 1) * n + i - 1] + 1e-12);
                }
                let qtq = mm(&tr(q, n, n), q, n, n, n);
                for i in 0..n {
                    assert!((qtq[i * n + i] - 1.0).abs() < 1e-12);
                }
            }
            reference.ql = m.q_left.clone();
            reference.qr = m.q_right.clone();
        }
        for k in 0..r * c {
            assert!(
                (p[k] - w[k]).abs() < 1e-9,
                "step {step}, weight {k}: {} against {}",
                p[k],
                w[k]
            );
        }
    }
    // The weights moved: the comparison is not of two idle states.
    assert!((p[0] - (0.0f64).sin()).abs() > 1e-3);
}

#[test]
fn the_state_round_trips_through_its_bytes_and_refuses_others() {
    let mut s = SoapState::<f32>::new(SoapConfig::default(), &[[2, 3], [3, 1]]);
    let mut p: Vec<f32> = (0..16).map(|k| k as f32 * 0.1).collect();
    for k in 0..3 {
        let g: Vec<f32> = (0..16).map(|i| ((i + k) as f32).sin()).collect();
        s.update(&mut p, &g, 1e-2);
    }
    let bytes = s.to_bytes();
    assert!(SoapState::is_fused(&bytes));
    let mut back = SoapState::<f32>::new(SoapConfig::default(), &[[2, 3], [3, 1]]);
    back.read_bytes(&bytes).unwrap();
    assert_eq!(back.to_bytes(), bytes);
    let mut other = SoapState::<f32>::new(SoapConfig::default(), &[[2, 4], [4, 1]]);
    let err = other.read_bytes(&bytes).unwrap_err();
    assert!(err.contains("buffer 1 holds 9 values"), "{err}");
    for cut in [10, 40, bytes.len() - 1] {
        let err = back.read_bytes(&bytes[..cut]).unwrap_err();
        assert!(
            err.contains("truncated") || err.contains("written"),
            "{err}"
        );
    }
    let mut long = bytes.clone();
    long.push(0);
    assert!(back.read_bytes(&long).unwrap_err().contains("too many"));
    // A failed read leaves the state as it was.
    assert_eq!(back.to_bytes(), bytes);
}

#[test]
fn a_soap_step_by_hand() {
    // One 2×2 weight and its bias. Step 1 starts the factors; step 2 is checked
    // against the algorithm written out with the exact eigenvectors.
    let c = SoapConfig::default();
    let mut s = SoapState::<f64>::new(c, &[[2, 2]]);
    let mut p = vec![1.0, 2.0, 3.0, 4.0, 0.5, -0.5];
    let g1 = vec![0.3, 0.0, 0.0, -0.2, 0.1, 0.2];
    s.update(&mut p, &g1, 0.1);
    // The weights did not move; the bias took an Adam step of size lr (|m̂/√v̂| = 1).
    assert_eq!(&p[..4], &[1.0, 2.0, 3.0, 4.0]);
    assert!(
        (p[4] - 0.4).abs() < 1e-6 && (p[5] + 0.6).abs() < 1e-6,
        "{p:?}"
    );
    // G₁ is diagonal, so both bases are the identity, sorted: L = diag(0.09, 0.04),
    // R = diag(0.09, 0.04), already in descending order.
    let g2 = vec![0.1, 0.0, 0.0, 0.4, 0.0, 0.0];
    s.update(&mut p, &g2, 0.1);
    // t = 1 for the matrix: m = 0.05 g, v = 0.05 g², step = lr √0.05 / 0.05 · m/(√v+ε)
    // = lr · sign(g) where g ≠ 0 (up to ε).
    let expect = [1.0 - 0.1, 2.0, 3.0, 4.0 - 0.1];
    for k in 0..4 {
        assert!((p[k] - expect[k]).abs() < 1e-6, "p[{k}] = {}", p[k]);
    }
}
