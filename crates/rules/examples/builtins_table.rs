//! Prints the built-in functions as a Markdown table (for the README).
fn main() {
    println!("| function | signature | what |");
    println!("|---|---|---|");
    for (name, sig, doc) in topomech_rules::builtins::full_catalogue() {
        println!("| `{name}` | `{sig}` | {doc} |");
    }
}
