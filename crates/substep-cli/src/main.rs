fn main() {
    println!("substep");
}
