//! Prints what the build script baked: the report and where the baked scenes are.

const REPORT: &str = include_str!(concat!(env!("OUT_DIR"), "/report.json"));

fn main() {
    println!("baked into {}/baked:", env!("OUT_DIR"));
    println!("{REPORT}");
}
