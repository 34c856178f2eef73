# Shared by the reference scripts of this folder (source()d by each; run them from the
# repository root): where the inputs and outputs live, how numbers are written, how an
# input is read, and the datasets each script covers.

here <- "analysis/reference_r"

# Every numeric column as text with 17 significant digits (round-trips a double exactly).
fmt <- function(df) {
  for (col in names(df)) if (is.numeric(df[[col]])) df[[col]] <- sprintf("%.17g", df[[col]])
  df
}

# One committed input (long format: subject, Density, Viewpoint, Method, y), factors set.
read_input <- function(name) {
  d <- read.csv(file.path(here, paste0(name, ".csv")), stringsAsFactors = FALSE)
  for (f in c("subject", "Density", "Viewpoint", "Method")) d[[f]] <- factor(d[[f]])
  d
}

# Write a data frame (numbers through fmt) as ref_<stem>.csv in this folder.
write_ref <- function(df, stem) {
  write.csv(fmt(df), file.path(here, paste0("ref_", stem, ".csv")), row.names = FALSE)
}

# The complete within-subject datasets (make_inputs.py).
complete_datasets <- c("spherical_5x4x2", "violated_5x4x2", "likert_5x2x2")

# ref_<stem>.csv: the version of each package ("R" for R itself) that wrote the references.
write_versions <- function(stem, packages) {
  v <- vapply(packages, function(p) {
    if (p == "R") paste(R.version$major, R.version$minor, sep = ".") else as.character(packageVersion(p))
  }, "")
  write.csv(data.frame(package = packages, version = unname(v)), file.path(here, paste0("ref_", stem, ".csv")),
            row.names = FALSE)
}

# The complete datasets with more than two methods (make_inputs.py): afex_reference.R
# covers them too.
k_method_datasets <- c("likert_5x2x3")
