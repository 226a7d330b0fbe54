use library::*;
fn main() {
    let seed: u64 = std::env::args().nth(1).map(|s| s.parse().unwrap()).unwrap_or(1);
    let s = LibrarySettings { seed, ..LibrarySettings::default() };
    let mut passes = vec![];
    let t = std::time::Instant::now();
    let lib = Library::build(&dynamics::Scene::flicking_finger(), &s, |_, e| passes.push(e.passes)).unwrap();
    let el = t.elapsed().as_secs_f64();
    let sum = |a: usize, b: usize| passes[a.min(passes.len())..b.min(passes.len())].iter().map(|&p| p as u64).sum::<u64>();
    let branch_first: u64 = (0..15).map(|b| passes[100 + 20 * b] as u64).sum();
    println!("seed {seed}: {el:.1}s, {} traj, trunk {} passes, branches {} (first of each {}), growth {} over {} traj", passes.len(), sum(0, 100), sum(100, 400), branch_first, sum(400, passes.len()), passes.len().saturating_sub(400));
    let _ = lib;
}
