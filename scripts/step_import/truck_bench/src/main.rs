//! Reads STEP files with truck-stepio 0.3.0 and tessellates each shell with truck-meshalgo:
//! shells, how many convert and tessellate, how many meshes are closed, triangles, the summed
//! signed volume (in the file's numbers: truck does not read the STEP length unit) and time.

use std::time::Instant;
use truck_meshalgo::prelude::*;
use truck_stepio::r#in::*;

fn volume(m: &PolygonMesh) -> f64 {
    let p = m.positions();
    let mut v = 0.0;
    for t in m.faces().triangle_iter() {
        let a = p[t[0].pos]; let b = p[t[1].pos]; let c = p[t[2].pos];
        v += a.to_vec().dot(b.to_vec().cross(c.to_vec())) / 6.0;
    }
    v
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let tol: f64 = args[1].parse().unwrap();
    for path in &args[2..] {
        let t0 = Instant::now();
        let text = std::fs::read_to_string(path).unwrap();
        let r = std::panic::catch_unwind(|| {
            let exchange = match ruststep::parser::parse(&text) { Ok(e) => e, Err(e) => { return format!("parse error: {e}"); } };
            let table = Table::from_data_section(&exchange.data[0]);
            let tparse = t0.elapsed().as_secs_f64();
            let mut ok = 0; let mut fail = 0; let mut closed = 0; let mut tris = 0; let mut vol = 0.0;
            let mut ids: Vec<_> = table.shell.keys().copied().collect(); ids.sort();
            for id in ids {
                let shell = &table.shell[&id];
                match table.to_compressed_shell(shell) {
                    Ok(s) => {
                        let poly = s.robust_triangulation(tol);
                        let mut m = poly.to_polygon();
                        m.put_together_same_attrs(tol * 1e-3);
                        let faces_ok = poly.faces.iter().all(|f| f.surface.is_some());
                        if !faces_ok { fail += 1; continue; }
                        ok += 1;
                        if m.shell_condition() == ShellCondition::Closed { closed += 1; }
                        tris += m.faces().triangle_iter().count();
                        vol += volume(&m);
                    }
                    Err(_) => fail += 1,
                }
            }
            format!("shells {} converted {ok} failed {fail} closed {closed} tris {tris} vol {vol:.1} parse {tparse:.2}s total {:.2}s", table.shell.len(), t0.elapsed().as_secs_f64())
        });
        match r { Ok(s) => println!("{path}: {s}"), Err(_) => println!("{path}: PANIC after {:.2}s", t0.elapsed().as_secs_f64()) }
    }
}
