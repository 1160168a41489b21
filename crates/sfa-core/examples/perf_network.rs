//! Per-layer, per-pass training time of the Table 5.2 network (600x60 RGB,
//! step 5, whole panorama, field cache on) on synthetic smooth panoramas:
//! `cargo run --release --example perf_network -p sfa-core -- [N] [mixed|double]`.
//! Prints ms per image for every pass (reading the images or the field
//! cache), and for the solve and cache advance after it, the basis of the
//! profile in docs/benchmarks.md. Trains with `sfa_core::fit`, timed through
//! its progress reports.
use sfa_core::network::{LayerSpec, Network, NetworkSpec};
use sfa_core::{fit, CachePolicy, FitOptions, InMemory, Progress, ProgressEvent, Rotation, SfaError};
use std::time::Instant;

fn images(n: usize, h: usize, w: usize, c: usize) -> Vec<f64> {
    let mut out = Vec::with_capacity(n * h * w * c);
    for i in 0..n {
        let t = i as f64 * 0.03;
        for y in 0..h {
            for x in 0..w {
                let a = 2.0 * std::f64::consts::PI * x as f64 / w as f64;
                for ch in 0..c {
                    let mut v = 0.5;
                    for f in 1..7 {
                        let ff = f as f64;
                        v += (1.0 / ff)
                            * (1.0 + 0.5 * (0.1 * y as f64 * ff + ch as f64).sin())
                            * (ff * a + t * (0.3 + 0.1 * ff) + ch as f64 * 1.7).sin();
                    }
                    // a little deterministic noise
                    let k = (i * 7919 + y * 104729 + x * 131 + ch * 17) as u64;
                    v += ((k.wrapping_mul(2654435761) % 1000) as f64 / 1000.0 - 0.5) * 0.04;
                    out.push(v);
                }
            }
        }
    }
    out
}

/// Process CPU seconds (user + system) from /proc/self/stat (Linux; 0 elsewhere):
/// on a shared machine CPU time is steadier than wall time.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let fields: Vec<&str> = stat.rsplit(')').next().unwrap_or("").split_whitespace().collect();
    let tick = |i: usize| fields.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (tick(11) + tick(12)) / 100.0
}

fn main() {
    let n: usize = std::env::args().nth(1).map_or(32, |a| a.parse().unwrap());
    let mixed = std::env::args().nth(2).map_or(true, |a| a == "mixed");
    let layer = |rf, stride, n_out| LayerSpec { rf, stride, n_out, reduce_to: None, degree: 2 };
    let spec = NetworkSpec {
        height: 60,
        width: 600,
        channels: 3,
        layers: vec![
            layer((12, 12), (6, 6), 12),
            layer((5, 5), (2, 2), 14),
            layer((6, 3), (3, 1), 16),
            layer((15, 1), (1, 1), 8),
        ],
        weight_sharing: true,
        tol: 1e-10,
        mixed_precision: mixed,
    };
    let mut net = Network::new(spec).unwrap();
    let imgs = images(n, 60, 600, 3);
    let rot = Rotation { step: 5, period: 600 };
    let batch = 16;
    let mut opts = FitOptions::new(rot);
    opts.cache = CachePolicy::Always;
    // PERF_PASSES=k stops after k passes (for profiling one pass).
    let max_passes: usize = std::env::var("PERF_PASSES").ok().and_then(|v| v.parse().ok()).unwrap_or(usize::MAX);
    let mut passes_done = 0;
    let total = Instant::now();
    let total_cpu = cpu_seconds();
    // (wall, cpu) at the last pass start and end.
    let mut started = (Instant::now(), 0.0);
    let mut ended: Option<(Instant, f64)> = None;
    let mut report = |p: &Progress| {
        match p.event {
            ProgressEvent::Start => {
                if let Some((t, _)) = ended {
                    println!("  solve / advance cache: {:.0} ms", 1e3 * t.elapsed().as_secs_f64());
                }
                started = (Instant::now(), cpu_seconds());
            }
            ProgressEvent::Finish => {
                let (feed, feed_cpu) = (started.0.elapsed().as_secs_f64(), cpu_seconds() - started.1);
                println!(
                    "layer {} pass {}{}: {:.1} ms/image, cpu {:.1} ms/image",
                    p.layer + 1,
                    p.pass + 1,
                    if p.cached { " (cached)" } else { "" },
                    1e3 * feed / n as f64,
                    1e3 * feed_cpu / n as f64,
                );
                ended = Some((Instant::now(), cpu_seconds()));
                passes_done += 1;
                if passes_done == max_passes {
                    return Err(SfaError::Interrupted("PERF_PASSES reached".into()));
                }
            }
            ProgressEvent::Advance => {}
        }
        Ok(())
    };
    match fit(&mut net, &mut InMemory::new(&imgs, n, batch).unwrap(), &opts, &mut report) {
        Ok(_) => {}
        Err(SfaError::Interrupted(_)) => return,
        Err(e) => panic!("{e}"),
    }
    println!(
        "total {:.1} ms/image, cpu {:.1} ms/image ({} images, {}, {} threads)",
        1e3 * total.elapsed().as_secs_f64() / n as f64,
        1e3 * (cpu_seconds() - total_cpu) / n as f64,
        n,
        if mixed { "mixed" } else { "double" },
        rayon::current_num_threads()
    );
}
