//! Ellipse contact on the scene's poses: apart and penetrating, value and derivatives, and parry's GJK/EPA.

use criterion::{Criterion, criterion_group, criterion_main};
use geometry::{Ellipse, parry_estimate, signed_distance_coords};
use std::hint::black_box;

fn contact(c: &mut Criterion) {
    let finger = Ellipse::new(0.8, 0.25).expect("valid");
    let free = Ellipse::new(0.7, 0.5).expect("valid");
    let free_pose = [0.0, -3.0, 0.3];
    for (name, finger_pose) in [
        ("apart", [0.0, -1.0, -1.2]),
        ("penetrating", [0.0, -2.3, -1.2]),
    ] {
        c.bench_function(&format!("signed_distance/{name}"), |b| {
            b.iter(|| {
                signed_distance_coords(&finger, black_box(finger_pose), &free, free_pose)
                    .map(|r| r.gradient())
            })
        });
        c.bench_function(&format!("signed_distance_derivatives/{name}"), |b| {
            b.iter(|| {
                signed_distance_coords(&finger, black_box(finger_pose), &free, free_pose)
                    .map(|r| r.derivatives())
            })
        });
        c.bench_function(&format!("parry_gjk_epa/{name}"), |b| {
            b.iter(|| parry_estimate(&finger, black_box(finger_pose), &free, free_pose))
        });
    }
}

criterion_group!(benches, contact);
criterion_main!(benches);
