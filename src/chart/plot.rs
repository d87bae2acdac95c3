//! The speed-accuracy SVG: one log–log panel per scene, error against
//! seconds, one curve per setting (points are ray counts), the scene's
//! Pareto front drawn as a thick dashed black line through ringed points.

use plotters::prelude::*;

use super::Row;

/// Panel size in pixels.
const PANEL: (u32, u32) = (640, 420);

/// Renders the rows as an SVG document.
pub fn render_svg(rows: &[Row]) -> Result<String, String> {
    let mut scenes: Vec<&str> = Vec::new();
    for r in rows {
        if !scenes.contains(&r.scene.as_str()) {
            scenes.push(&r.scene);
        }
    }
    let columns = 2u32;
    let panel_rows = (scenes.len() as u32).div_ceil(columns).max(1);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (PANEL.0 * columns, PANEL.1 * panel_rows)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let areas = root.split_evenly((panel_rows as usize, columns as usize));
        for (scene, area) in scenes.iter().zip(areas.iter()) {
            draw_panel(area, scene, rows).map_err(|e| e.to_string())?;
        }
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

type Area<'a> = DrawingArea<SVGBackend<'a>, plotters::coord::Shift>;

fn draw_panel(area: &Area, scene: &str, rows: &[Row]) -> Result<(), Box<dyn std::error::Error>> {
    let points: Vec<&Row> = rows.iter().filter(|r| r.scene == scene && r.error > 0.0 && r.seconds > 0.0).collect();
    if points.is_empty() {
        return Ok(());
    }
    let (mut t0, mut t1, mut e0, mut e1) = (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64);
    for r in &points {
        t0 = t0.min(r.seconds);
        t1 = t1.max(r.seconds);
        e0 = e0.min(r.error);
        e1 = e1.max(r.error);
    }
    let (t0, t1, e0, e1) = (t0 / 1.3, t1 * 1.3, e0 / 1.5, e1 * 1.5);
    let mut chart = ChartBuilder::on(area)
        .caption(format!("{scene}: shaded error vs seconds"), ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(60)
        .build_cartesian_2d((t0..t1).log_scale(), (e0..e1).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("seconds")
        .y_desc("relative RMS error")
        .x_label_formatter(&|x| format!("{x:.2}"))
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .draw()?;
    let mut settings: Vec<&str> = Vec::new();
    for r in &points {
        if !settings.contains(&r.setting.as_str()) {
            settings.push(&r.setting);
        }
    }
    for (k, setting) in settings.iter().enumerate() {
        let colour = Palette99::pick(k).to_rgba();
        let mut curve: Vec<(f64, f64)> = points.iter().filter(|r| r.setting == *setting).map(|r| (r.seconds, r.error)).collect();
        curve.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(curve.clone(), colour.stroke_width(2)))?
            .label(setting.to_string())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2)));
        chart.draw_series(curve.iter().map(|&p| Circle::new(p, 3, colour.filled())))?;
    }
    let mut front: Vec<(f64, f64)> = points.iter().filter(|r| r.pareto).map(|r| (r.seconds, r.error)).collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    chart
        .draw_series(DashedLineSeries::new(front.clone(), 6, 4, BLACK.stroke_width(2)))?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK.stroke_width(2)));
    chart.draw_series(front.iter().map(|&p| Circle::new(p, 6, BLACK.stroke_width(1))))?;
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", 11))
        .draw()?;
    Ok(())
}
