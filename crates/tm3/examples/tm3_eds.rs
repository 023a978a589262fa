//! Prints the EDS of a TM3 island: `cargo run -p cantwin-tm3 --example tm3_eds -- TM3DI16 TM3DQ16T TM3AI4`.

use cantwin_tm3::island::Island;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let refs: Vec<String> = std::env::args().skip(1).collect();
    let island = Island::from_references(&refs)?;
    print!("{}", cantwin_tm3::eds::eds_text(&island)?);
    Ok(())
}
