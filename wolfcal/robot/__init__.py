"""wolfcal.robot"""
