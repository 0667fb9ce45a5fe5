# Sourced by scripts/reproduce_paper_models.sh and scripts/compare_paper_models.sh (run from the repository root).
# paper_points FILE: every shipped paper-* material, one name per line, each followed by its quality points that
# hold FILE (assets/NAME/POINT/FILE, named NAME/POINT; docs/formats.md "Quality points").
paper_points() {
    local file=$1 folder point
    for folder in assets/paper-*/; do
        basename "$folder"
        for point in "$folder"*/"$file"; do
            if [ -f "$point" ]; then echo "$(basename "$folder")/$(basename "$(dirname "$point")")"; fi
        done
    done
}
